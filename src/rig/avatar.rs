//! Stand-ins for downloaded avatar rigs (`furrow rig generate --kind avatar | avatar-parts |
//! avatar-clip`), small enough for fast tests, shaped as real ones are: a skin whose shapes
//! fold it by design (lips pressed or rolled in, lids closed onto each other;
//! [`super::avatar_shapes`]) and, beside the skin, eyes, teeth, lashes and a mouth interior
//! carrying the same target list.
//!
//! - [`avatar`]: a Ready Player Me–style avatar (float glTF): a stub body skinned to the chain
//!   Hips → Spine → Neck → Head, the head ([`HEAD_NAME`], ~2,000 vertices, the 52 ARKit
//!   shapes and 15 visemes), the eyes (`EyeLeft`, `EyeRight`) and the teeth (`Teeth`), each a
//!   mesh skinned rigidly to Head with the head's targets (position deltas only, as many
//!   exporters write them, which keeps the file near half a megabyte); one opaque material
//!   per mesh.
//! - [`avatar_parts`]: a VRoid-style face (compact glTF: quantized, meshopt-compressed): one
//!   mesh ([`FACE_NAME`]) of five primitives with a material each: the skin, two eyeballs,
//!   alpha-masked double-sided lash cards along the upper lids, and a mouth interior pocket
//!   behind the lips; the same targets on every primitive.
//! - [`avatar_clip`]: the avatar and a 2.5 s weights animation at 30 fps through a blink, a
//!   lip press, a lip roll and `viseme_PP`, driving the head, eyes and teeth alike.
//!
//! The head is made at the origin; in the avatar it sits at [`HEAD_OFFSET`] on the body. The
//! skin's texture coordinates are a cylindrical projection about the vertical axis, with the
//! seam at the back of the head (its vertices doubled there, so the loader's weld has seams
//! to join as on a real rig). Deterministic.

use super::avatar_head::{self, AvatarHead};
use super::avatar_meshes::{
    body, eye_shapes, eyeball, jaw_shapes, lash_shapes, lashes, mouth_pocket, teeth, Surface,
};
use super::avatar_shapes::{head_shapes, Shapes};
use super::head::HALF_HEIGHT;
use crate::io::compact::scene::{
    scene_glb, Alpha, Influences, Material, Mesh, Node, Primitive, Scene, Skin, Storage, WeightClip,
};
use crate::io::model::{MorphTarget, WeightKeys};
use crate::mesh::TriMesh;
use nalgebra::Vector3;
use std::collections::HashMap;

/// Where the head's origin sits in the avatar's body space, m.
pub const HEAD_OFFSET: [f64; 3] = [0.0, 1.64, 0.0];
/// Heights of the joints Hips, Spine, Neck and Head in the body's space, m.
pub const JOINT_HEIGHTS: [f64; 4] = [1.0, 1.15, 1.47, 1.56];
/// Name of the avatar's head mesh and node.
pub const HEAD_NAME: &str = "AvatarHead";
/// Name of the parts face's mesh and node.
pub const FACE_NAME: &str = "Face";
/// Key rate of the clip, frames per second.
pub const CLIP_FPS: f64 = 30.0;
/// Length of the clip, s.
pub const CLIP_DURATION: f64 = 2.5;

/// A generated avatar: its scene, how it is stored, and its skin as written.
#[derive(Debug, Clone)]
pub struct AvatarRig {
    /// The whole scene.
    pub scene: Scene,
    /// Float or compact.
    pub storage: Storage,
    /// The skin as written (m, in the scene's space; seam vertices doubled).
    pub skin: TriMesh,
    /// The skin's targets (deltas in m).
    pub targets: Vec<MorphTarget>,
    /// The clip's keys (empty without a clip).
    pub keys: WeightKeys,
}

impl AvatarRig {
    /// The rig as GLB bytes.
    pub fn glb(&self) -> anyhow::Result<Vec<u8>> {
        scene_glb(&self.scene, self.storage)
    }
}

/// Position deltas under this length are written as zero, m (a hundredth of a millimetre).
pub const TRIM_POSITION: f64 = 1e-5;
/// Normal deltas under this length are written as zero.
pub const TRIM_NORMAL: f64 = 1e-3;

/// `d` with every vector shorter than `tol` set to zero (the fields' faint tails, so sparse
/// targets list only the vertices a shape visibly moves).
fn trimmed(d: &[Vector3<f64>], tol: f64) -> Vec<Vector3<f64>> {
    d.iter()
        .map(|v| if v.norm() < tol { Vector3::zeros() } else { *v })
        .collect()
}

/// A morph target named `name` of position deltas `d` (m) on `mesh` with rest normals
/// `normals`, both trimmed ([`TRIM_POSITION`], [`TRIM_NORMAL`]).
fn target(name: &str, mesh: &TriMesh, normals: &[Vector3<f64>], d: &[Vector3<f64>]) -> MorphTarget {
    let positions = trimmed(d, TRIM_POSITION);
    MorphTarget {
        name: name.into(),
        normals: Some(trimmed(
            &mesh.normal_deltas(normals, &positions),
            TRIM_NORMAL,
        )),
        positions,
    }
}

/// Morph targets of `surface` from `shapes`, with normal deltas against its normals.
fn targets_of(surface: &Surface, shapes: &Shapes) -> Vec<MorphTarget> {
    shapes
        .iter()
        .map(|(name, d)| target(name, &surface.mesh, &surface.normals, d))
        .collect()
}

/// `surface` and its targets moved by `offset` (m).
fn placed(mut surface: Surface, offset: Vector3<f64>) -> Surface {
    for p in &mut surface.mesh.positions {
        *p += offset;
    }
    surface
}

/// The head's skin as written: the seamless head with each ring's back vertex doubled (the
/// copy on the −X side of the seam), its texture coordinates, and its targets.
fn skin(head: &AvatarHead, shapes: &Shapes) -> (Surface, Vec<MorphTarget>) {
    let n = head.mesh.positions.len();
    let normals = head.mesh.vertex_normals();
    let mut original: Vec<usize> = (0..n).collect();
    let mut copy_of = HashMap::new();
    for ring in head.rings.iter().skip(1) {
        if ring.len() % 2 == 0 {
            copy_of.insert(ring[ring.len() / 2], original.len());
            original.push(ring[ring.len() / 2]);
        }
    }
    let on_seam = |v: &usize| copy_of.contains_key(v);
    let triangles = head
        .mesh
        .triangles
        .iter()
        .map(|t| {
            let west = t
                .iter()
                .any(|v| !on_seam(v) && *v != 0 && head.base[*v].x < 0.0);
            if west {
                t.map(|v| *copy_of.get(&v).unwrap_or(&v))
            } else {
                *t
            }
        })
        .collect();
    let uvs = (0..original.len())
        .map(|i| {
            let b = head.base[original[i]];
            let u = if i >= n {
                0.0
            } else if on_seam(&i) {
                1.0
            } else if i == 0 {
                0.5
            } else {
                0.5 + b.x.atan2(b.z) / std::f64::consts::TAU
            };
            [u, (HALF_HEIGHT - b.y) / (2.0 * HALF_HEIGHT)]
        })
        .collect();
    let spread = |v: &[Vector3<f64>]| original.iter().map(|&o| v[o]).collect::<Vec<_>>();
    let targets = shapes
        .iter()
        .map(|(name, d)| {
            let t = target(name, &head.mesh, &normals, d);
            MorphTarget {
                name: t.name,
                positions: spread(&t.positions),
                normals: t.normals.as_deref().map(spread),
            }
        })
        .collect();
    let surface = Surface {
        mesh: TriMesh::new(spread(&head.mesh.positions), triangles),
        normals: spread(&normals),
        uvs,
    };
    (surface, targets)
}

/// A primitive of `surface` with `targets`, `material` and influences `infl`.
fn primitive(
    surface: Surface,
    targets: Vec<MorphTarget>,
    material: usize,
    infl: Option<Vec<Influences>>,
) -> Primitive {
    Primitive {
        mesh: surface.mesh,
        normals: surface.normals,
        uvs: surface.uvs,
        targets,
        material,
        influences: infl,
    }
}

/// `targets` without their normal deltas.
fn positions_only(targets: &[MorphTarget]) -> Vec<MorphTarget> {
    targets
        .iter()
        .map(|t| MorphTarget {
            normals: None,
            ..t.clone()
        })
        .collect()
}

/// A mesh of one primitive rigidly skinned to joint 3 (Head), its targets written without
/// normal deltas.
fn head_part(name: &str, surface: Surface, targets: Vec<MorphTarget>, material: usize) -> Mesh {
    let targets = positions_only(&targets);
    let infl = vec![Influences::rigid(3); surface.mesh.positions.len()];
    Mesh {
        name: name.into(),
        primitives: vec![primitive(surface, targets, material, Some(infl))],
    }
}

/// The avatar's materials: body, skin, each eye, teeth.
fn avatar_materials() -> Vec<Material> {
    vec![
        Material::opaque("Body", [0.25, 0.32, 0.45, 1.0], 0.8),
        Material::opaque("Skin", [0.87, 0.68, 0.58, 1.0], 0.6),
        Material::opaque("EyeLeft", [0.95, 0.95, 0.93, 1.0], 0.2),
        Material::opaque("EyeRight", [0.95, 0.95, 0.93, 1.0], 0.2),
        Material::opaque("Teeth", [0.93, 0.91, 0.84, 1.0], 0.35),
    ]
}

/// The avatar's node tree: Armature → Hips → Spine → Neck → Head (joints), then the skinned
/// mesh nodes Body, the head, EyeLeft, EyeRight and Teeth as roots (nodes 5 to 9).
fn avatar_nodes() -> Vec<Node> {
    let joint = |name: &str, dy: f64, child: Option<usize>| Node {
        name: name.into(),
        translation: Vector3::new(0.0, dy, 0.0),
        children: child.into_iter().collect(),
        ..Node::default()
    };
    let j = JOINT_HEIGHTS;
    let mut nodes = vec![
        Node {
            name: "Armature".into(),
            children: vec![1],
            ..Node::default()
        },
        joint("Hips", j[0], Some(2)),
        joint("Spine", j[1] - j[0], Some(3)),
        joint("Neck", j[2] - j[1], Some(4)),
        joint("Head", j[3] - j[2], None),
    ];
    for (k, name) in ["Body", HEAD_NAME, "EyeLeft", "EyeRight", "Teeth"]
        .into_iter()
        .enumerate()
    {
        nodes.push(Node {
            name: name.into(),
            mesh: Some(k),
            skin: Some(0),
            ..Node::default()
        });
    }
    nodes
}

/// The avatar (see the module notes). Deterministic.
pub fn avatar() -> AvatarRig {
    let head = avatar_head::generate();
    let shapes = head_shapes(&head);
    let offset = Vector3::from(HEAD_OFFSET);
    let (skin_surface, skin_targets) = skin(&head, &shapes);
    let skin_surface = placed(skin_surface, offset);
    let mut meshes = Vec::new();
    let (b, infl) = body(&JOINT_HEIGHTS);
    meshes.push(Mesh {
        name: "Body".into(),
        primitives: vec![primitive(b, Vec::new(), 0, Some(infl))],
    });
    meshes.push(head_part(
        HEAD_NAME,
        skin_surface.clone(),
        skin_targets.clone(),
        1,
    ));
    for (k, (name, sx)) in [("EyeLeft", 1.0), ("EyeRight", -1.0)]
        .into_iter()
        .enumerate()
    {
        let eye = eyeball(head.eyes[k]);
        let targets = targets_of(&eye, &eye_shapes(&eye.mesh.positions, head.eyes[k], sx));
        meshes.push(head_part(name, placed(eye, offset), targets, 2 + k));
    }
    let (t, w) = teeth(&head);
    let targets = targets_of(&t, &jaw_shapes(&t.mesh.positions, &w));
    meshes.push(head_part("Teeth", placed(t, offset), targets, 4));
    let scene = Scene {
        nodes: avatar_nodes(),
        roots: vec![0, 5, 6, 7, 8, 9],
        meshes,
        materials: avatar_materials(),
        skins: vec![Skin {
            name: "Armature".into(),
            joints: vec![1, 2, 3, 4],
        }],
        clip: None,
    };
    AvatarRig {
        scene,
        storage: Storage::Float,
        skin: skin_surface.mesh,
        targets: positions_only(&skin_targets),
        keys: WeightKeys::default(),
    }
}

/// The VRoid-style face (see the module notes). Deterministic.
pub fn avatar_parts() -> AvatarRig {
    let head = avatar_head::generate();
    let shapes = head_shapes(&head);
    let (skin_surface, skin_targets) = skin(&head, &shapes);
    let mut prims = vec![primitive(
        skin_surface.clone(),
        skin_targets.clone(),
        0,
        None,
    )];
    for (k, sx) in [1.0, -1.0].into_iter().enumerate() {
        let eye = eyeball(head.eyes[k]);
        let targets = targets_of(&eye, &eye_shapes(&eye.mesh.positions, head.eyes[k], sx));
        prims.push(primitive(eye, targets, 1 + k, None));
    }
    let (l, follow) = lashes(&head);
    let targets = targets_of(&l, &lash_shapes(&follow, &shapes));
    prims.push(primitive(l, targets, 3, None));
    let (m, w) = mouth_pocket(&head);
    let targets = targets_of(&m, &jaw_shapes(&m.mesh.positions, &w));
    prims.push(primitive(m, targets, 4, None));
    let lash_material = Material {
        alpha: Alpha::Mask(0.5),
        double_sided: true,
        ..Material::opaque("Lashes", [0.05, 0.04, 0.04, 1.0], 0.7)
    };
    let scene = Scene {
        nodes: vec![Node {
            name: FACE_NAME.into(),
            mesh: Some(0),
            ..Node::default()
        }],
        roots: vec![0],
        meshes: vec![Mesh {
            name: FACE_NAME.into(),
            primitives: prims,
        }],
        materials: vec![
            Material::opaque("FaceSkin", [0.96, 0.84, 0.78, 1.0], 0.6),
            Material::opaque("EyeWhiteLeft", [0.95, 0.95, 0.93, 1.0], 0.2),
            Material::opaque("EyeWhiteRight", [0.95, 0.95, 0.93, 1.0], 0.2),
            lash_material,
            Material::opaque("MouthInterior", [0.55, 0.2, 0.22, 1.0], 0.5),
        ],
        skins: Vec::new(),
        clip: None,
    };
    AvatarRig {
        scene,
        storage: Storage::Compact,
        skin: skin_surface.mesh,
        targets: skin_targets,
        keys: WeightKeys::default(),
    }
}

/// The clip's events: (start s, duration s, shapes each rising to weight 1).
const CLIP_EVENTS: [(f64, f64, &[&str]); 4] = [
    (0.15, 0.55, &["eyeBlinkLeft", "eyeBlinkRight"]),
    (0.65, 0.6, &["mouthPressLeft", "mouthPressRight"]),
    (1.2, 0.6, &["mouthRollLower", "mouthRollUpper"]),
    (1.75, 0.6, &["viseme_PP"]),
];

/// Envelope of an event at normalised time `u`: a smoothstep rise over the first 40 %, a hold
/// at 1, a smoothstep fall over the last 40 %; 0 outside [0, 1].
fn envelope(u: f64) -> f64 {
    if !(0.0..=1.0).contains(&u) {
        return 0.0;
    }
    let rise = |t: f64| t * t * (3.0 - 2.0 * t);
    rise((u / 0.4).min(1.0)) * rise(((1.0 - u) / 0.4).min(1.0))
}

/// The clip's keys for targets `names`: [`CLIP_DURATION`] at [`CLIP_FPS`] through
/// [`CLIP_EVENTS`], every other weight 0.
pub fn clip_keys(names: &[&str]) -> WeightKeys {
    let frames = (CLIP_DURATION * CLIP_FPS).round() as usize;
    let times: Vec<f64> = (0..=frames).map(|k| k as f64 / CLIP_FPS).collect();
    let weights = times
        .iter()
        .map(|&t| {
            let mut w = vec![0.0; names.len()];
            for (start, duration, shapes) in CLIP_EVENTS {
                let e = envelope((t - start) / duration);
                for s in shapes {
                    if let Some(i) = names.iter().position(|n| n == s) {
                        w[i] = f64::max(w[i], e);
                    }
                }
            }
            w
        })
        .collect();
    WeightKeys { times, weights }
}

/// The avatar with its clip (see the module notes). Deterministic.
pub fn avatar_clip() -> AvatarRig {
    let mut rig = avatar();
    let names: Vec<&str> = rig.targets.iter().map(|t| t.name.as_str()).collect();
    let keys = clip_keys(&names);
    rig.scene.clip = Some(WeightClip {
        name: "folds".into(),
        keys: keys.clone(),
        nodes: vec![6, 7, 8, 9],
    });
    rig.keys = keys;
    rig
}
