//! The face mesh's parts: which of its primitives are skin and which ride along.
//!
//! A real face mesh is more than skin: eyeballs, irises, lash and brow cards, teeth, tongue,
//! the mouth interior and shading cards sit beside it as primitives of the same mesh. They
//! ride along: they keep their own shapes and are written back unchanged, never welded,
//! refined or simulated. The skin is decided from the material and the geometry:
//!
//! 1. a primitive drawn with alpha blending or an alpha mask (a lash or brow card, a tear
//!    film, an occlusion layer) rides along;
//! 2. the other triangle primitives are welded by position into connected surfaces; the
//!    skin is the largest surface the blend shapes move, and any other open surface the
//!    shapes move of at least [`JOINED_SKIN_AREA`] of its area (a face made of pieces);
//! 3. a primitive is skin when most of its area lies on skin surfaces; a closed surface apart
//!    from the skin (an eyeball) or a small open one (teeth, gums, a mouth pocket) rides
//!    along.
//!
//! A user's list (`[rig] skin_primitives`, `--skin-primitives`: primitive indices or material
//! names) overrides the rule.

use super::mesh::MeshInstance;
use crate::mesh::grid::PointGrid;
use nalgebra::Vector3;
use serde::Serialize;
use std::fmt;

/// A surface apart from the largest moved one is skin too when it is open, moved by the
/// shapes, and at least this fraction of that surface's area.
pub const JOINED_SKIN_AREA: f64 = 0.2;

/// Vertices closer than this fraction of the face's bounding-box diagonal are one point when
/// surfaces are found (seams split vertices at exactly the same place).
const JOIN_TOLERANCE: f64 = 1e-6;

/// A primitive of the face mesh named by the user: by its index in the mesh or its
/// material's name.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum PrimitivePick {
    /// The primitive's index in the face mesh's `primitives`.
    Index(usize),
    /// The name of the primitive's material.
    Material(String),
}

impl fmt::Display for PrimitivePick {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Index(i) => write!(f, "{i}"),
            Self::Material(m) => write!(f, "{m:?}"),
        }
    }
}

/// Parse a comma-separated list of primitive indices and material names
/// (`--skin-primitives 0,1` or `--skin-primitives M_Face,M_BackHead`).
pub fn parse_picks(text: &str) -> Result<Vec<PrimitivePick>, String> {
    let picks: Vec<PrimitivePick> = text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| match s.parse::<usize>() {
            Ok(i) => PrimitivePick::Index(i),
            Err(_) => PrimitivePick::Material(s.to_string()),
        })
        .collect();
    if picks.is_empty() {
        return Err("expected a comma-separated list of primitive indices or material names, e.g. `0,1` or `M_Face,M_BackHead`".into());
    }
    Ok(picks)
}

/// Why a primitive is skin or rides along.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PartReason {
    /// Skin: on the largest surface the blend shapes move (welded by position).
    LargestMoved,
    /// Skin: an open surface of its own the shapes move, large beside the skin.
    LargeOpen,
    /// Skin: named in the user's list.
    Chosen,
    /// Rides along: drawn with alpha blending (a card or a shading layer).
    AlphaBlend,
    /// Rides along: drawn with an alpha mask (a lash or brow card).
    AlphaMask,
    /// Rides along: a closed surface apart from the skin (an eyeball, teeth).
    ClosedApart,
    /// Rides along: a small open surface apart from the skin (teeth, gums, a mouth pocket).
    OpenApart,
    /// Rides along: not named in the user's list.
    NotChosen,
    /// Rides along: not made of triangles (points or lines).
    NotTriangles,
}

impl PartReason {
    /// Whether the reason makes the primitive skin.
    pub fn is_skin(self) -> bool {
        matches!(self, Self::LargestMoved | Self::LargeOpen | Self::Chosen)
    }

    /// The reason in words.
    pub fn describe(self) -> &'static str {
        match self {
            Self::LargestMoved => "on the largest surface the blend shapes move",
            Self::LargeOpen => "an open surface the shapes move, large beside the skin",
            Self::Chosen => "named in the skin list",
            Self::AlphaBlend => "alpha-blended (a card or shading layer)",
            Self::AlphaMask => "alpha-masked (a lash or brow card)",
            Self::ClosedApart => "a closed surface apart from the skin (an eyeball, teeth)",
            Self::OpenApart => {
                "a small open surface apart from the skin (teeth, gums, a mouth pocket)"
            }
            Self::NotChosen => "not named in the skin list",
            Self::NotTriangles => "not triangles",
        }
    }
}

/// One primitive of the face mesh and its part.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FacePart {
    /// The primitive's index in the face mesh's `primitives`.
    pub primitive: usize,
    /// Its material's name, when it has one.
    pub material: Option<String>,
    /// Whether it is skin (else it rides along, unchanged).
    pub skin: bool,
    /// Why.
    pub reason: PartReason,
    /// Its triangle count.
    pub triangles: usize,
}

/// The parts of the face mesh, one per primitive in the mesh's order.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct FaceParts {
    /// Every primitive's part.
    pub parts: Vec<FacePart>,
}

impl FaceParts {
    /// Per span of `face` (its triangle primitives, in order): whether it is skin.
    pub fn skin_spans(&self, face: &MeshInstance) -> Vec<bool> {
        face.primitives
            .iter()
            .map(|s| self.parts.iter().any(|p| p.primitive == s.json && p.skin))
            .collect()
    }

    /// The primitives that ride along.
    pub fn riding(&self) -> impl Iterator<Item = &FacePart> {
        self.parts.iter().filter(|p| !p.skin)
    }

    /// What was taken as skin and what rides along, in one sentence.
    pub fn summary(&self) -> String {
        let name = |p: &FacePart| match &p.material {
            Some(m) => format!("{} ({m})", p.primitive),
            None => p.primitive.to_string(),
        };
        let list = |skin: bool| -> Vec<String> {
            self.parts
                .iter()
                .filter(|p| p.skin == skin)
                .map(|p| format!("{}: {}", name(p), p.reason.describe()))
                .collect()
        };
        let (skin, riding) = (list(true), list(false));
        if riding.is_empty() {
            return format!("skin: every primitive of the face ({})", skin.join("; "));
        }
        format!(
            "skin: primitive {}; riding along unchanged: {}",
            skin.join("; "),
            riding.join("; ")
        )
    }
}

/// What a primitive is made of, as the classification sees it.
struct Primitive<'a> {
    json: usize,
    material: Option<String>,
    alpha: Option<&'a str>,
    triangles: Option<Vec<usize>>,
}

/// Classify the primitives of `face` (its mesh's JSON `mesh_json`, the file's `materials`):
/// by `picks` when given, else by the rule of the module doc. An error names what the list
/// asks for that the mesh lacks, or says that nothing is skin.
pub fn classify(
    face: &MeshInstance,
    mesh_json: &serde_json::Value,
    materials: &serde_json::Value,
    picks: Option<&[PrimitivePick]>,
) -> Result<FaceParts, String> {
    let prims = primitives_of(face, mesh_json, materials);
    let parts = match picks {
        Some(picks) => chosen(&prims, picks)?,
        None => by_rule(face, &prims),
    };
    if !parts.iter().any(|p| p.skin) {
        return Err(format!(
            "no primitive of the face '{}' is skin: {}; name the skin with --skin-primitives",
            face.name,
            FaceParts {
                parts: parts.clone()
            }
            .summary()
        ));
    }
    Ok(FaceParts { parts })
}

/// Every primitive of the face mesh with its material, alpha mode and, for triangle
/// primitives, its merged triangles.
fn primitives_of<'a>(
    face: &MeshInstance,
    mesh_json: &serde_json::Value,
    materials: &'a serde_json::Value,
) -> Vec<Primitive<'a>> {
    let count = mesh_json["primitives"].as_array().map_or(0, Vec::len);
    let mut by_span: Vec<Vec<usize>> = vec![Vec::new(); face.primitives.len()];
    for (t, tri) in face.triangles.iter().enumerate() {
        let s = face.primitives.partition_point(|s| s.first <= tri[0]) - 1;
        by_span[s].push(t);
    }
    (0..count)
        .map(|j| {
            let m = mesh_json["primitives"][j]["material"].as_u64();
            let mat = m.map(|m| &materials[m as usize]);
            Primitive {
                json: j,
                material: mat.and_then(|m| m["name"].as_str()).map(String::from),
                alpha: mat.and_then(|m| m["alphaMode"].as_str()),
                triangles: face
                    .primitives
                    .iter()
                    .position(|s| s.json == j)
                    .map(|s| std::mem::take(&mut by_span[s])),
            }
        })
        .collect()
}

/// The parts a user's list names (an error names a pick the mesh lacks).
fn chosen(prims: &[Primitive], picks: &[PrimitivePick]) -> Result<Vec<FacePart>, String> {
    let named = |p: &Primitive, pick: &PrimitivePick| match pick {
        PrimitivePick::Index(i) => p.json == *i,
        PrimitivePick::Material(m) => p.material.as_deref() == Some(m.as_str()),
    };
    if let Some(pick) = picks.iter().find(|k| !prims.iter().any(|p| named(p, k))) {
        let have: Vec<String> = prims
            .iter()
            .map(|p| match &p.material {
                Some(m) => format!("{} ({m})", p.json),
                None => p.json.to_string(),
            })
            .collect();
        return Err(format!(
            "the skin list names primitive {pick}, which the face mesh lacks; its primitives: {}",
            have.join(", ")
        ));
    }
    Ok(prims
        .iter()
        .map(|p| {
            let reason = match &p.triangles {
                None => PartReason::NotTriangles,
                Some(_) if picks.iter().any(|k| named(p, k)) => PartReason::Chosen,
                Some(_) => PartReason::NotChosen,
            };
            part(p, reason)
        })
        .collect())
}

fn part(p: &Primitive, reason: PartReason) -> FacePart {
    FacePart {
        primitive: p.json,
        material: p.material.clone(),
        skin: reason.is_skin(),
        reason,
        triangles: p.triangles.as_ref().map_or(0, Vec::len),
    }
}

/// The parts by the rule of the module doc.
fn by_rule(face: &MeshInstance, prims: &[Primitive]) -> Vec<FacePart> {
    let opaque = |p: &Primitive| !matches!(p.alpha, Some("BLEND") | Some("MASK"));
    let candidates: Vec<usize> = prims
        .iter()
        .filter(|p| opaque(p))
        .filter_map(|p| p.triangles.as_ref())
        .flatten()
        .copied()
        .collect();
    let surfaces = Surfaces::of(face, &candidates);
    let mut parts: Vec<FacePart> = prims
        .iter()
        .map(|p| {
            let reason = match (&p.triangles, p.alpha) {
                (None, _) => PartReason::NotTriangles,
                (Some(_), Some("BLEND")) => PartReason::AlphaBlend,
                (Some(_), Some("MASK")) => PartReason::AlphaMask,
                (Some(tris), _) => surfaces.reason(face, tris),
            };
            part(p, reason)
        })
        .collect();
    // A face of many small pieces (a low-poly head, a test mesh) may have no primitive whose
    // area lies mostly on the main surface: the opaque primitive holding most of it is skin.
    if !parts.iter().any(|p| p.skin) {
        let on_main = |p: &Primitive| {
            p.triangles
                .as_ref()
                .filter(|_| opaque(p))
                .map_or(0.0, |t| surfaces.area_on_main(face, t))
        };
        let best = (0..prims.len())
            .filter(|&j| on_main(&prims[j]) > 0.0)
            .max_by(|&a, &b| on_main(&prims[a]).total_cmp(&on_main(&prims[b])));
        if let Some(j) = best {
            parts[j] = part(&prims[j], PartReason::LargestMoved);
        }
    }
    parts
}

/// The connected surfaces of a set of triangles, welded by position.
struct Surfaces {
    /// Surface of each triangle of the face (`usize::MAX` for triangles not considered).
    of_triangle: Vec<usize>,
    /// Whether each surface is closed (every welded edge shared by two triangles).
    closed: Vec<bool>,
    /// Whether each surface is skin.
    skin: Vec<bool>,
    /// The largest surface the shapes move (or the largest).
    main: usize,
}

impl Surfaces {
    fn of(face: &MeshInstance, triangles: &[usize]) -> Self {
        let point = weld_points(face, triangles);
        let mut sets = DisjointSets::new(face.positions.len());
        for &t in triangles {
            let [a, b, c] = face.triangles[t].map(|v| point[v]);
            sets.join(a, b);
            sets.join(b, c);
        }
        let mut id = std::collections::HashMap::new();
        let mut of_triangle = vec![usize::MAX; face.triangles.len()];
        for &t in triangles {
            let root = sets.root(point[face.triangles[t][0]]);
            let next = id.len();
            of_triangle[t] = *id.entry(root).or_insert(next);
        }
        let n = id.len();
        let (mut area, mut moved) = (vec![0.0; n], vec![false; n]);
        let mut edges: Vec<std::collections::HashMap<(usize, usize), u32>> =
            vec![Default::default(); n];
        let still = JOIN_TOLERANCE * diagonal(face);
        for &t in triangles {
            let s = of_triangle[t];
            let tri = face.triangles[t];
            let [a, b, c] = tri.map(|v| face.positions[v]);
            area[s] += 0.5 * (b - a).cross(&(c - a)).norm();
            moved[s] |= tri
                .iter()
                .any(|&v| face.targets.iter().any(|m| m.positions[v].norm() > still));
            for k in 0..3 {
                let (u, w) = (point[tri[k]], point[tri[(k + 1) % 3]]);
                *edges[s].entry((u.min(w), u.max(w))).or_default() += 1;
            }
        }
        let closed: Vec<bool> = edges.iter().map(|e| e.values().all(|&c| c == 2)).collect();
        let largest = |pool: &mut dyn Iterator<Item = usize>| {
            pool.max_by(|&a, &b| area[a].total_cmp(&area[b]))
        };
        let main = largest(&mut (0..n).filter(|&s| moved[s]))
            .or_else(|| largest(&mut (0..n)))
            .unwrap_or(0);
        let skin = (0..n)
            .map(|s| {
                s == main || (moved[s] && !closed[s] && area[s] >= JOINED_SKIN_AREA * area[main])
            })
            .collect();
        Self {
            of_triangle,
            closed,
            skin,
            main,
        }
    }

    /// The area of triangles `tris` on the main surface (world units²).
    fn area_on_main(&self, face: &MeshInstance, tris: &[usize]) -> f64 {
        tris.iter()
            .filter(|&&t| self.of_triangle[t] == self.main)
            .map(|&t| {
                let [a, b, c] = face.triangles[t].map(|v| face.positions[v]);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum()
    }

    /// Why a primitive of `tris` is skin or rides along: by the surface holding most of its
    /// area.
    fn reason(&self, face: &MeshInstance, tris: &[usize]) -> PartReason {
        let mut share = std::collections::HashMap::<usize, f64>::new();
        let mut on_skin = 0.0;
        let mut total = 0.0;
        for &t in tris {
            let [a, b, c] = face.triangles[t].map(|v| face.positions[v]);
            let area = 0.5 * (b - a).cross(&(c - a)).norm();
            let s = self.of_triangle[t];
            *share.entry(s).or_default() += area;
            total += area;
            if self.skin[s] {
                on_skin += area;
            }
        }
        let Some((&s, _)) = share
            .iter()
            .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(a.0)))
        else {
            return PartReason::OpenApart;
        };
        if on_skin >= 0.5 * total && total > 0.0 {
            if s == self.main {
                PartReason::LargestMoved
            } else {
                PartReason::LargeOpen
            }
        } else if self.closed[s] {
            PartReason::ClosedApart
        } else {
            PartReason::OpenApart
        }
    }
}

/// The face's bounding-box diagonal (world units).
fn diagonal(face: &MeshInstance) -> f64 {
    let (lo, hi) = face.positions.iter().fold(
        (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        ),
        |(lo, hi), p| (lo.inf(p), hi.sup(p)),
    );
    let d = (hi - lo).norm();
    if d.is_finite() {
        d
    } else {
        0.0
    }
}

/// For each vertex of the face, the first vertex of `triangles` at its place (within
/// [`JOIN_TOLERANCE`] of the diagonal); vertices not on those triangles map to themselves.
fn weld_points(face: &MeshInstance, triangles: &[usize]) -> Vec<usize> {
    let tol = (JOIN_TOLERANCE * diagonal(face)).max(f64::MIN_POSITIVE);
    let mut point: Vec<usize> = (0..face.positions.len()).collect();
    let mut used = vec![false; face.positions.len()];
    triangles
        .iter()
        .flat_map(|&t| face.triangles[t])
        .for_each(|v| used[v] = true);
    let mut grid = PointGrid::new(tol, []);
    for v in (0..face.positions.len()).filter(|&v| used[v]) {
        let p = &face.positions[v];
        let found = grid
            .near(p)
            .find(|&u| (face.positions[u] - p).norm() <= tol);
        match found {
            Some(u) => point[v] = u,
            None => grid.insert(v, p),
        }
    }
    point
}

/// Union–find over `n` items.
struct DisjointSets {
    parent: Vec<usize>,
}

impl DisjointSets {
    fn new(n: usize) -> Self {
        Self {
            parent: (0..n).collect(),
        }
    }

    fn root(&mut self, mut a: usize) -> usize {
        while self.parent[a] != a {
            self.parent[a] = self.parent[self.parent[a]];
            a = self.parent[a];
        }
        a
    }

    fn join(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.root(a), self.root(b));
        if ra != rb {
            self.parent[ra.max(rb)] = ra.min(rb);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::mesh::{PrimitiveSpan, VertexTransform};
    use crate::io::model::MorphTarget;
    use crate::mesh::TriMesh;
    use nalgebra::Matrix4;
    use serde_json::json;

    /// A face mesh of `parts` (mesh, whether its shape moves it) as one instance, one
    /// primitive each, with one morph target.
    fn face_of(parts: &[(TriMesh, bool)]) -> MeshInstance {
        let (mut positions, mut triangles, mut spans, mut lift) = (vec![], vec![], vec![], vec![]);
        for (j, (m, moved)) in parts.iter().enumerate() {
            let first = positions.len();
            spans.push(PrimitiveSpan {
                json: j,
                first,
                count: m.positions.len(),
            });
            positions.extend(&m.positions);
            triangles.extend(m.triangles.iter().map(|t| t.map(|v| v + first)));
            let d = if *moved { 0.01 } else { 0.0 };
            lift.extend(m.positions.iter().map(|_| Vector3::new(0.0, 0.0, d)));
        }
        MeshInstance {
            node: 0,
            mesh: 0,
            name: "face".into(),
            positions,
            normals: None,
            triangles,
            targets: vec![MorphTarget {
                name: "lift".into(),
                positions: lift,
                normals: None,
            }],
            default_weights: vec![0.0],
            to_world: VertexTransform::Node(Matrix4::identity()),
            primitives: spans,
            skipped_primitives: 0,
        }
    }

    /// An n × n vertex grid `size` wide (m) in the z = 0 plane, its corner at `at`.
    fn sheet(n: usize, size: f64, at: Vector3<f64>) -> TriMesh {
        let h = size / (n - 1) as f64;
        let p = (0..n * n)
            .map(|i| at + Vector3::new((i % n) as f64 * h, (i / n) as f64 * h, 0.0))
            .collect();
        TriMesh::new(p, crate::mesh::grid_triangles(n, n))
    }

    fn cube(a: f64, at: Vector3<f64>) -> TriMesh {
        let mut m = crate::mesh::cube_mesh(a, 2);
        m.positions.iter_mut().for_each(|p| *p += at);
        m
    }

    /// Skin (a sheet the shape moves) split in two primitives along a seam, an eyeball (a
    /// closed cube apart), teeth (a small open sheet apart) and a lash card (alpha-blended).
    fn avatar_face() -> (MeshInstance, serde_json::Value, serde_json::Value) {
        let left = sheet(9, 0.2, Vector3::zeros());
        let right = sheet(9, 0.2, Vector3::new(0.2, 0.0, 0.0));
        let parts = [
            (left, true),
            (right, true),
            (cube(0.02, Vector3::new(0.0, 0.0, -0.05)), true),
            (sheet(3, 0.03, Vector3::new(0.0, -0.05, -0.05)), true),
            (sheet(3, 0.03, Vector3::new(0.0, 0.05, 0.02)), true),
        ];
        let mesh = json!({ "primitives": [
            { "material": 0 }, { "material": 0 }, { "material": 1 }, { "material": 2 },
            { "material": 3 }, { "material": 3, "mode": 1 } ] });
        let materials = json!([
            { "name": "skin" }, { "name": "eye" }, { "name": "teeth" },
            { "name": "lashes", "alphaMode": "BLEND" } ]);
        (face_of(&parts), mesh, materials)
    }

    #[test]
    fn skin_eyes_teeth_and_cards_are_told_apart() {
        let (face, mesh, materials) = avatar_face();
        let parts = classify(&face, &mesh, &materials, None).unwrap();
        let reasons: Vec<PartReason> = parts.parts.iter().map(|p| p.reason).collect();
        assert_eq!(
            reasons,
            vec![
                PartReason::LargestMoved,
                PartReason::LargestMoved,
                PartReason::ClosedApart,
                PartReason::OpenApart,
                PartReason::AlphaBlend,
                PartReason::NotTriangles,
            ]
        );
        assert_eq!(
            parts.skin_spans(&face),
            vec![true, true, false, false, false]
        );
        assert_eq!(parts.riding().count(), 4);
        let said = parts.summary();
        assert!(
            said.contains("1 (skin)") && said.contains("4 (lashes)"),
            "{said}"
        );
    }

    #[test]
    fn a_large_open_surface_the_shapes_move_is_skin_too() {
        let parts = [
            (sheet(9, 0.2, Vector3::zeros()), true),
            (sheet(9, 0.15, Vector3::new(1.0, 0.0, 0.0)), true),
            (sheet(9, 0.15, Vector3::new(2.0, 0.0, 0.0)), false),
        ];
        let face = face_of(&parts);
        let mesh = json!({ "primitives": [{}, {}, {}] });
        let p = classify(&face, &mesh, &json!([]), None).unwrap();
        let reasons: Vec<PartReason> = p.parts.iter().map(|p| p.reason).collect();
        assert_eq!(
            reasons,
            vec![
                PartReason::LargestMoved,
                PartReason::LargeOpen,
                PartReason::OpenApart
            ]
        );
    }

    #[test]
    fn a_face_of_many_small_closed_pieces_keeps_the_piece_holding_the_main_surface() {
        // A low-poly head: one primitive of three separate closed blocks, a second of one.
        let mut blocks = cube(0.1, Vector3::zeros());
        for k in 1..3 {
            let more = cube(0.1, Vector3::new(0.3 * k as f64, 0.0, 0.0));
            let first = blocks.positions.len();
            blocks.positions.extend(&more.positions);
            blocks
                .triangles
                .extend(more.triangles.iter().map(|t| t.map(|v| v + first)));
        }
        let parts = [
            (blocks, true),
            (cube(0.05, Vector3::new(0.0, 1.0, 0.0)), true),
        ];
        let face = face_of(&parts);
        let mesh = json!({ "primitives": [{}, {}] });
        let p = classify(&face, &mesh, &json!([]), None).unwrap_or_else(|e| panic!("{e}"));
        let reasons: Vec<PartReason> = p.parts.iter().map(|p| p.reason).collect();
        assert_eq!(
            reasons,
            vec![PartReason::LargestMoved, PartReason::ClosedApart]
        );
    }

    #[test]
    fn a_list_picks_the_skin_by_index_or_material_and_names_what_it_lacks() {
        let (face, mesh, materials) = avatar_face();
        let picks = parse_picks("0, teeth").unwrap();
        assert_eq!(
            picks,
            vec![
                PrimitivePick::Index(0),
                PrimitivePick::Material("teeth".into())
            ]
        );
        let p = classify(&face, &mesh, &materials, Some(&picks)).unwrap_or_else(|e| panic!("{e}"));
        let skin: Vec<usize> = p
            .parts
            .iter()
            .filter(|p| p.skin)
            .map(|p| p.primitive)
            .collect();
        assert_eq!(skin, vec![0, 3]);
        assert_eq!(p.parts[1].reason, PartReason::NotChosen);
        let e = classify(&face, &mesh, &materials, Some(&parse_picks("7").unwrap())).unwrap_err();
        assert!(e.contains("primitive 7") && e.contains("3 (teeth)"), "{e}");
        let e = classify(&face, &mesh, &materials, Some(&parse_picks("5").unwrap())).unwrap_err();
        assert!(e.contains("no primitive of the face"), "{e}");
        assert!(parse_picks(" , ").is_err());
    }
}
