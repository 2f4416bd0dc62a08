//! Loading a blend-shape rig: the file, its mesh instances in world space, the face mesh and
//! its morph-weight animation.

use super::accessor::{usize_of, AccessorReader};
use super::animation::{self, AnimationInfo, WeightTrack};
use super::container::{self, Container, ReadOptions};
use super::error::{GltfError, GltfResult};
use super::mesh::{self, MeshInstance};
use super::parts::{self, FaceParts, PrimitivePick};
use super::scene;
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// What to pick from a file.
#[derive(Debug, Clone, Default)]
pub struct LoadOptions {
    /// Face mesh by mesh or node name, or by mesh index; default: the most morph targets.
    pub mesh: Option<String>,
    /// Animation by name or index; default: the first that animates the face's weights.
    pub animation: Option<String>,
    /// The face mesh's skin primitives by index or material name; default: decided from
    /// the materials and the geometry ([`super::parts`]).
    pub skin_primitives: Option<Vec<PrimitivePick>>,
    /// Read buffer and image files outside the rig's folder (absolute paths, `..`, symlinks
    /// out); refused by default.
    pub allow_outside_paths: bool,
}

impl LoadOptions {
    /// How the file itself is read.
    pub fn read(&self) -> ReadOptions {
        ReadOptions {
            allow_outside_paths: self.allow_outside_paths,
        }
    }
}

/// A loaded rig: every mesh instance and the chosen face with its weight animation.
pub struct Rig {
    /// The file it came from.
    pub path: PathBuf,
    /// The parsed file (JSON kept verbatim for re-export, and decoded buffers).
    pub container: Container,
    /// Every node that instances a mesh, in world space.
    pub instances: Vec<MeshInstance>,
    /// Index into `instances` of the face mesh (all its primitives).
    pub face: usize,
    /// The face's skin: the face mesh restricted to its skin primitives (what is welded,
    /// refined and simulated; [`Rig::face`]).
    pub skin: MeshInstance,
    /// Which primitives of the face mesh are skin and which ride along, and why.
    pub parts: FaceParts,
    /// Why that mesh was taken (said to the user).
    pub face_reason: String,
    /// Every animation in the file.
    pub animations: Vec<AnimationInfo>,
    /// Index of the animation driving the face, if any.
    pub animation: Option<usize>,
    /// The face's weight track in that animation.
    pub track: Option<WeightTrack>,
    /// The face node's rigid motion in that animation (a head that turns and nods), if its
    /// node or an ancestor is animated.
    pub motion: Option<super::motion::NodeMotion>,
    /// Extensions the file uses.
    pub extensions_used: Vec<String>,
    /// The scale it is simulated at (metres per file unit; set by [`Rig::rescale`]).
    pub scale: super::model::RigScale,
}

impl Rig {
    /// The face's skin: the face mesh instance restricted to its skin primitives (the
    /// primitives that ride along are left out; [`Rig::parts`] says which).
    pub fn face(&self) -> &MeshInstance {
        &self.skin
    }

    /// The face mesh instance with every primitive, skin and riding along.
    pub fn face_mesh(&self) -> &MeshInstance {
        &self.instances[self.face]
    }

    /// Morph weights per frame at `fps` (one frame of default weights without animation).
    pub fn frame_weights(&self, fps: f64) -> Vec<Vec<f64>> {
        match &self.track {
            Some(t) => t.sample_frames(fps),
            None => vec![self.face().default_weights.clone()],
        }
    }

    /// Per-vertex attribute `name` of the face (its vertex order), e.g. `TEXCOORD_0` or a
    /// custom `_THICKNESS`; the error names the file, the mesh and the primitive without it.
    pub fn face_attribute(&self, name: &str) -> GltfResult<mesh::VertexAttribute> {
        let reader = AccessorReader::new(&self.path, &self.container);
        mesh::read_attribute(&self.path, &reader, &self.container.json, self.face(), name)
    }

    /// The blended face (world, m) for one weight vector: base + Σ w_t Δ_t.
    pub fn blend(&self, weights: &[f64]) -> Vec<Vector3<f64>> {
        let f = self.face();
        let mut p = f.positions.clone();
        for (t, &w) in f.targets.iter().zip(weights) {
            if w != 0.0 {
                for (pi, d) in p.iter_mut().zip(&t.positions) {
                    *pi += d * w;
                }
            }
        }
        p
    }
}

/// Load every mesh instance of the file at `path` without choosing a face (for `inspect`),
/// with the default [`ReadOptions`].
pub fn load_instances(
    path: &Path,
) -> GltfResult<(Container, Vec<MeshInstance>, Vec<AnimationInfo>)> {
    load_instances_with(path, ReadOptions::default())
}

/// Load every mesh instance of the file at `path`, read with `opts`, without choosing a face.
pub fn load_instances_with(
    path: &Path,
    opts: ReadOptions,
) -> GltfResult<(Container, Vec<MeshInstance>, Vec<AnimationInfo>)> {
    let c = container::read(path, opts)?;
    let (inst, anims) = instances_of(path, &c)?;
    Ok((c, inst, anims))
}

fn instances_of(path: &Path, c: &Container) -> GltfResult<(Vec<MeshInstance>, Vec<AnimationInfo>)> {
    let reader = AccessorReader::new(path, c);
    let (world, order) = scene::world_matrices(path, &c.json)?;
    let mut inst = Vec::new();
    let mut in_scene: Vec<usize> = order
        .iter()
        .copied()
        .filter(|&n| c.json["nodes"][n]["mesh"].is_u64())
        .collect();
    in_scene.sort_unstable();
    for n in in_scene {
        inst.push(mesh::extract(path, &reader, &c.json, n, &world)?);
    }
    let anims = animation::summarize(path, &reader, &c.json)?;
    Ok((inst, anims))
}

/// Surface area of a mesh instance (world units²).
fn area(m: &MeshInstance) -> f64 {
    m.triangles
        .iter()
        .map(|t| {
            0.5 * (m.positions[t[1]] - m.positions[t[0]])
                .cross(&(m.positions[t[2]] - m.positions[t[0]]))
                .norm()
        })
        .sum()
}

/// The default face among the instances with morph targets (`morphs`): of those whose
/// targets move some vertex, the one with the most targets, and among equals the largest
/// surface (an avatar carries the same shapes on its head, eyes and teeth: the head is the
/// face); the reason names the other meshes that carried targets.
fn pick_face(
    instances: &[MeshInstance],
    morphs: &[usize],
    describe: impl Fn(usize) -> String,
) -> (usize, String) {
    let moves = |i: usize| {
        instances[i]
            .targets
            .iter()
            .any(|t| t.positions.iter().any(|d| d.norm_squared() > 0.0))
    };
    let moving: Vec<usize> = morphs.iter().copied().filter(|&i| moves(i)).collect();
    let pool = if moving.is_empty() { morphs } else { &moving };
    let best = pool
        .iter()
        .copied()
        .max_by(|&a, &b| {
            let key = |i: usize| (instances[i].targets.len(), area(&instances[i]));
            let (ka, kb) = (key(a), key(b));
            ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1)).then(b.cmp(&a))
        })
        .expect("non-empty");
    if morphs.len() == 1 {
        return (best, format!("face {}", describe(best)));
    }
    let others: Vec<String> = morphs
        .iter()
        .filter(|&&i| i != best)
        .map(|&i| describe(i))
        .collect();
    let reason = format!(
        "face {} chosen as the mesh with the most morph targets that move vertices, the largest \
         surface among equals; {} other mesh(es) carry targets: {} (use --mesh to pick another)",
        describe(best),
        others.len(),
        others.join(", ")
    );
    (best, reason)
}

/// Load the rig at `path` and choose its face and animation.
pub fn load(path: &Path, opts: &LoadOptions) -> GltfResult<Rig> {
    let c = container::read(path, opts.read())?;
    load_container(path, c, opts)
}

/// Load a rig from bytes that came from `path` (which names errors and anchors relative URIs).
pub fn load_bytes(path: &Path, bytes: &[u8], opts: &LoadOptions) -> GltfResult<Rig> {
    let c = container::parse(path, bytes, opts.read())?;
    load_container(path, c, opts)
}

fn load_container(path: &Path, c: Container, opts: &LoadOptions) -> GltfResult<Rig> {
    let (instances, animations) = instances_of(path, &c)?;
    let morphs: Vec<usize> = (0..instances.len())
        .filter(|&i| !instances[i].targets.is_empty())
        .collect();
    if morphs.is_empty() {
        return Err(GltfError::new(path, format!(
            "no mesh with morph targets (blend shapes) in the displayed scene ({} mesh instances); furrow needs a blend-shape rig",
            instances.len()
        )));
    }
    let describe = |i: usize| {
        let m = &instances[i];
        format!(
            "'{}' (mesh {}, node {}, {} targets)",
            m.name,
            m.mesh,
            m.node,
            m.targets.len()
        )
    };
    let (face, face_reason) = match &opts.mesh {
        Some(want) => {
            let found = morphs.iter().copied().find(|&i| {
                let m = &instances[i];
                m.name == *want
                    || c.json["nodes"][m.node]["name"].as_str() == Some(want.as_str())
                    || want.parse::<usize>().ok() == Some(m.mesh)
            });
            match found {
                Some(i) => (i, format!("face {} chosen by --mesh {want}", describe(i))),
                None => {
                    let list: Vec<String> = morphs.iter().map(|&i| describe(i)).collect();
                    return Err(GltfError::new(
                        path,
                        format!(
                            "no mesh with morph targets matches --mesh {want:?}; candidates: {}",
                            list.join(", ")
                        ),
                    ));
                }
            }
        }
        None => pick_face(&instances, &morphs, describe),
    };
    let reader = AccessorReader::new(path, &c);
    let node = instances[face].node;
    let nt = instances[face].targets.len();
    let animation = match &opts.animation {
        Some(want) => {
            let a = animations
                .iter()
                .find(|a| a.name == *want || want.parse::<usize>().ok() == Some(a.index))
                .ok_or_else(|| {
                    let names: Vec<&str> = animations.iter().map(|a| a.name.as_str()).collect();
                    GltfError::new(
                        path,
                        format!("no animation {want:?}; the file has: {}", names.join(", ")),
                    )
                })?;
            Some(a.index)
        }
        None => animations.iter().map(|a| a.index).find(|&ai| {
            c.json["animations"][ai]["channels"]
                .as_array()
                .is_some_and(|cs| {
                    cs.iter().any(|ch| {
                        ch["target"]["path"] == "weights"
                            && usize_of(&ch["target"]["node"]) == Some(node)
                    })
                })
        }),
    };
    let track = match animation {
        Some(ai) => animation::weight_track(path, &reader, &c.json, ai, node, nt)?,
        None => None,
    };
    let motion = match animation {
        Some(ai) => super::motion::node_motion(path, &reader, &c.json, ai, node)?,
        None => None,
    };
    let extensions_used = c.root.extensions_used.clone();
    drop(reader);
    let whole = &instances[face];
    let parts = parts::classify(
        whole,
        &c.json["meshes"][whole.mesh],
        &c.json["materials"],
        opts.skin_primitives.as_deref(),
    )
    .map_err(|e| GltfError::new(path, e))?;
    let skin = whole.restricted(&parts.skin_spans(whole)).0;
    Ok(Rig {
        path: path.to_path_buf(),
        container: c,
        instances,
        face,
        skin,
        parts,
        face_reason,
        animations,
        animation,
        track,
        motion,
        extensions_used,
        scale: Default::default(),
    })
}
