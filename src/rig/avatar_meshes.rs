//! The avatar's meshes beside the skin, in the head's space (m, +Y up, facing +Z): two
//! eyeballs, the teeth, the mouth interior, the lash cards, and the stub body (in the body's
//! space, standing on the origin). Each comes with texture coordinates and unit normals, and
//! each head part with deltas for every shape of the head ([`super::avatar_shapes`]): the
//! eyes turn with `eyeLook*`, the lower teeth and the mouth interior's floor follow the jaw,
//! the lashes follow the upper lid, and the visemes mix those as the head's do; every other
//! delta is zero.

use super::avatar_head::{lid_lens, AvatarHead, SlitCopy, EYE_RADIUS};
use super::avatar_shapes::{visemes, Shapes};
use super::head::EYE;
use super::head_shapes::{ARKIT_NAMES, JAW_ANGLE, JAW_FORWARD, JAW_PIVOT_YZ, JAW_SIDE};
use super::surface::smoothstep;
use crate::io::compact::scene::Influences;
use crate::mesh::fold::weld_by_position;
use crate::mesh::TriMesh;
use nalgebra::{Rotation3, Vector3};
use std::f64::consts::{PI, TAU};

/// Eye turn for `eyeLookUp*` and `eyeLookDown*` at weight 1, rad (20°).
pub const LOOK_VERTICAL: f64 = 20.0 * PI / 180.0;
/// Eye turn for `eyeLookIn*` and `eyeLookOut*` at weight 1, rad (25°).
pub const LOOK_HORIZONTAL: f64 = 25.0 * PI / 180.0;
/// Length of the lashes at the middle of the lid, m.
pub const LASH_LENGTH: f64 = 0.008;

/// A surface with texture coordinates and unit normals.
#[derive(Debug, Clone)]
pub struct Surface {
    /// Positions (m) and counter-clockwise triangles.
    pub mesh: TriMesh,
    /// Unit normals, one per vertex.
    pub normals: Vec<Vector3<f64>>,
    /// Texture coordinates, one per vertex.
    pub uvs: Vec<[f64; 2]>,
}

/// Turn every triangle whose normal points away from `outward(centroid)` (a direction).
fn orient(mesh: &mut TriMesh, outward: impl Fn(&Vector3<f64>) -> Vector3<f64>) {
    let p = &mesh.positions;
    for t in &mut mesh.triangles {
        let n = (p[t[1]] - p[t[0]]).cross(&(p[t[2]] - p[t[0]]));
        let c = (p[t[0]] + p[t[1]] + p[t[2]]) / 3.0;
        if n.dot(&outward(&c)) < 0.0 {
            t.swap(1, 2);
        }
    }
}

/// A closed latitude-longitude ellipsoid about `centre` (m) with radii `radii` (m), its poles
/// on the z axis: `rings` latitude bands of `segments` vertices each; the front pole first.
fn ellipsoid(centre: Vector3<f64>, radii: Vector3<f64>, rings: usize, segments: usize) -> TriMesh {
    let mut pos = vec![centre + Vector3::new(0.0, 0.0, radii.z)];
    for i in 1..rings {
        let th = PI * i as f64 / rings as f64;
        for j in 0..segments {
            let ph = TAU * j as f64 / segments as f64;
            let u = Vector3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
            pos.push(centre + u.component_mul(&radii));
        }
    }
    pos.push(centre - Vector3::new(0.0, 0.0, radii.z));
    let back = pos.len() - 1;
    let id = |i: usize, j: usize| 1 + (i - 1) * segments + j % segments;
    let mut tris = Vec::new();
    for j in 0..segments {
        tris.push([0, id(1, j), id(1, j + 1)]);
        tris.push([back, id(rings - 1, j + 1), id(rings - 1, j)]);
        for i in 1..rings - 1 {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh::new(pos, tris)
}

/// Texture coordinates projected from the front onto the box `centre` ± `half` (m).
fn front_uvs(pos: &[Vector3<f64>], centre: Vector3<f64>, half: (f64, f64)) -> Vec<[f64; 2]> {
    pos.iter()
        .map(|p| {
            let u = 0.5 + 0.5 * (p.x - centre.x) / half.0;
            let v = 0.5 - 0.5 * (p.y - centre.y) / half.1;
            [u.clamp(0.0, 1.0), v.clamp(0.0, 1.0)]
        })
        .collect()
}

/// The eyeball about `centre` (m): a closed sphere of [`EYE_RADIUS`], its front pole (the
/// cornea) facing +Z, texture coordinates projected from the front (the iris in the middle).
pub fn eyeball(centre: Vector3<f64>) -> Surface {
    let r = Vector3::repeat(EYE_RADIUS);
    let mut mesh = ellipsoid(centre, r, 12, 18);
    orient(&mut mesh, |c| c - centre);
    let normals = mesh.vertex_normals();
    let uvs = front_uvs(&mesh.positions, centre, (EYE_RADIUS, EYE_RADIUS));
    Surface { mesh, normals, uvs }
}

/// The ARKit deltas of the eye about `centre` on side `sx` (+1 left, −1 right): the look
/// shapes of its side turn it about its centre; the rest are zero.
fn eye_arkit(pos: &[Vector3<f64>], centre: Vector3<f64>, sx: f64) -> Shapes {
    let side = if sx > 0.0 { "Left" } else { "Right" };
    ARKIT_NAMES
        .iter()
        .map(|&name| {
            let rot = match name.strip_suffix(side) {
                Some("eyeLookUp") => Rotation3::from_axis_angle(&Vector3::x_axis(), -LOOK_VERTICAL),
                Some("eyeLookDown") => {
                    Rotation3::from_axis_angle(&Vector3::x_axis(), LOOK_VERTICAL)
                }
                Some("eyeLookIn") => {
                    Rotation3::from_axis_angle(&Vector3::y_axis(), -sx * LOOK_HORIZONTAL)
                }
                Some("eyeLookOut") => {
                    Rotation3::from_axis_angle(&Vector3::y_axis(), sx * LOOK_HORIZONTAL)
                }
                _ => Rotation3::identity(),
            };
            let d = pos
                .iter()
                .map(|p| rot * (p - centre) - (p - centre))
                .collect();
            (name.to_string(), d)
        })
        .collect()
}

/// Every shape's deltas (m) of the eye about `centre` on side `sx` (+1 left, −1 right).
pub fn eye_shapes(pos: &[Vector3<f64>], centre: Vector3<f64>, sx: f64) -> Shapes {
    with_visemes(eye_arkit(pos, centre, sx))
}

/// `arkit` followed by the visemes mixed from it.
fn with_visemes(mut arkit: Shapes) -> Shapes {
    let v = visemes(&arkit);
    arkit.extend(v);
    arkit
}

/// Every shape's deltas (m) of points `pos` that follow the jaw with weights `w` (0..1, one
/// per point): the jaw's shapes as the head's jaw moves ([`super::avatar_shapes::jaw_weight`]
/// whole), the rest zero.
pub fn jaw_shapes(pos: &[Vector3<f64>], w: &[f64]) -> Shapes {
    let pivot = Vector3::new(0.0, JAW_PIVOT_YZ.0, JAW_PIVOT_YZ.1);
    let turn = |p: &Vector3<f64>, a: f64| {
        Rotation3::from_axis_angle(&Vector3::x_axis(), a) * (p - pivot) - (p - pivot)
    };
    let arkit = ARKIT_NAMES
        .iter()
        .map(|&name| {
            let d = pos
                .iter()
                .zip(w)
                .map(|(p, &w)| {
                    w * match name {
                        "jawOpen" => turn(p, JAW_ANGLE),
                        "tongueOut" => turn(p, 0.3 * JAW_ANGLE),
                        "jawForward" => Vector3::z() * JAW_FORWARD,
                        "jawLeft" => Vector3::x() * JAW_SIDE,
                        "jawRight" => Vector3::x() * -JAW_SIDE,
                        _ => Vector3::zeros(),
                    }
                })
                .collect();
            (name.to_string(), d)
        })
        .collect();
    with_visemes(arkit)
}

/// One arch of teeth: a closed tube of elliptic section (6 mm thick, 9 mm tall) along a
/// horseshoe in the horizontal plane at height `y` (m), its front at `z_front` (m), `2a` m
/// across, of `stations` sections, with end caps. Texture coordinates projected from the
/// front.
pub fn teeth_arch(y: f64, z_front: f64, a: f64, stations: usize) -> Surface {
    let (b, max, section) = (0.022, 100f64.to_radians(), 8);
    let centre = |ph: f64| Vector3::new(a * ph.sin(), y, z_front - 0.003 - b * (1.0 - ph.cos()));
    let mut pos = Vec::new();
    let mut centres = Vec::new();
    for k in 0..stations {
        let ph = -max + 2.0 * max * k as f64 / (stations - 1) as f64;
        let c = centre(ph);
        let out = Vector3::new(b * ph.sin(), 0.0, a * ph.cos()).normalize();
        for j in 0..section {
            let ps = TAU * j as f64 / section as f64;
            pos.push(c + out * (0.003 * ps.cos()) + Vector3::y() * (0.0045 * ps.sin()));
        }
        centres.push(c);
    }
    let ends = [pos.len(), pos.len() + 1];
    pos.push(centres[0]);
    pos.push(centres[stations - 1]);
    let id = |k: usize, j: usize| k * section + j % section;
    let mut tris = Vec::new();
    let mut inside = Vec::new();
    for k in 0..stations - 1 {
        for j in 0..section {
            tris.push([id(k, j), id(k + 1, j), id(k + 1, j + 1)]);
            tris.push([id(k, j), id(k + 1, j + 1), id(k, j + 1)]);
            inside.extend([(centres[k] + centres[k + 1]) / 2.0; 2]);
        }
    }
    for j in 0..section {
        tris.push([ends[0], id(0, j), id(0, j + 1)]);
        tris.push([ends[1], id(stations - 1, j + 1), id(stations - 1, j)]);
        let step = centres[1] - centres[0];
        let last = centres[stations - 1] - centres[stations - 2];
        inside.push(centres[0] + step);
        inside.push(centres[stations - 1] - last);
    }
    let mut mesh = TriMesh::new(pos, tris);
    let p = mesh.positions.clone();
    for (t, c) in mesh.triangles.iter_mut().zip(&inside) {
        let n = (p[t[1]] - p[t[0]]).cross(&(p[t[2]] - p[t[0]]));
        if n.dot(&((p[t[0]] + p[t[1]] + p[t[2]]) / 3.0 - c)) < 0.0 {
            t.swap(1, 2);
        }
    }
    let normals = mesh.vertex_normals();
    let uvs = front_uvs(&mesh.positions, Vector3::new(0.0, y, 0.0), (a, 0.0045));
    Surface { mesh, normals, uvs }
}

/// Both arches of teeth behind the lips of `head` (upper then lower, one surface; the lower
/// arch a little narrower and coarser) and each vertex's jaw weight (0 on the upper arch, 1
/// on the lower).
pub fn teeth(head: &AvatarHead) -> (Surface, Vec<f64>) {
    let z_front = head.mesh.positions[head.rings[head.mouth_ring][0]].z - 0.008;
    let upper = teeth_arch(head.mouth_y + 0.0058, z_front, 0.022, 27);
    let lower = teeth_arch(head.mouth_y - 0.0054, z_front - 0.001, 0.0205, 23);
    let w: Vec<f64> = (0..upper.mesh.positions.len())
        .map(|_| 0.0)
        .chain((0..lower.mesh.positions.len()).map(|_| 1.0))
        .collect();
    (join(&[upper, lower]), w)
}

/// The surfaces as one (vertices concatenated).
fn join(parts: &[Surface]) -> Surface {
    let mut out = Surface {
        mesh: TriMesh::default(),
        normals: Vec::new(),
        uvs: Vec::new(),
    };
    for s in parts {
        let o = out.mesh.positions.len();
        out.mesh.positions.extend(&s.mesh.positions);
        out.mesh
            .triangles
            .extend(s.mesh.triangles.iter().map(|t| t.map(|v| v + o)));
        out.normals.extend(&s.normals);
        out.uvs.extend(&s.uvs);
    }
    out
}

/// The mouth interior of `head`: a pocket behind the lips (the back two thirds of an
/// ellipsoid 44 × 32 × 48 mm, open toward the lips, facing in), not joined to the skin; and
/// each vertex's jaw weight (the floor follows the jaw, the roof stays).
pub fn mouth_pocket(head: &AvatarHead) -> (Surface, Vec<f64>) {
    let front = head.mesh.positions[head.rings[head.mouth_ring][0]].z;
    let centre = Vector3::new(0.0, head.mouth_y, front - 0.033);
    let radii = Vector3::new(0.022, 0.016, 0.024);
    let full = ellipsoid(centre, radii, 12, 20);
    // Keep the back pole and the bands whose polar angle from the front is at least 60°.
    let keep: Vec<bool> = full
        .positions
        .iter()
        .map(|p| (p.z - centre.z) / radii.z <= 0.5 + 1e-9)
        .collect();
    let mut index = vec![usize::MAX; keep.len()];
    let mut pos = Vec::new();
    for (v, p) in full.positions.iter().enumerate() {
        if keep[v] {
            index[v] = pos.len();
            pos.push(*p);
        }
    }
    let tris = full
        .triangles
        .iter()
        .filter(|t| t.iter().all(|&v| keep[v]))
        .map(|t| t.map(|v| index[v]))
        .collect();
    let mut mesh = TriMesh::new(pos, tris);
    orient(&mut mesh, |c| centre - c);
    let normals = mesh.vertex_normals();
    let uvs = front_uvs(&mesh.positions, centre, (radii.x, radii.y));
    let w = mesh
        .positions
        .iter()
        .map(|p| smoothstep(head.mouth_y + 0.004, head.mouth_y - 0.006, p.y))
        .collect();
    (Surface { mesh, normals, uvs }, w)
}

/// The lash cards of both eyes of `head` (one surface): a strip of quads along each upper lid
/// margin, rooted 0.2 mm out from it and sweeping out and up, longest ([`LASH_LENGTH`]) at
/// the middle; u runs along the lid, v from the tips (0) to the roots (1). Also, for each
/// vertex, the hinge-row vertices (two, with weights) whose deltas it takes: the lid row just
/// above the margin, so the lashes ride the lid down in a blink.
pub fn lashes(head: &AvatarHead) -> (Surface, Vec<[(usize, f64); 2]>) {
    let normals = head.mesh.vertex_normals();
    let p = &head.mesh.positions;
    let hinge = head.front_row(head.eye_ring - 1, SlitCopy::None);
    let mut out = Surface {
        mesh: TriMesh::default(),
        normals: Vec::new(),
        uvs: Vec::new(),
    };
    let mut follow = Vec::new();
    for sx in [1.0, -1.0] {
        let mut margin: Vec<usize> = head.front_row(head.eye_ring, SlitCopy::None);
        margin
            .retain(|&v| sx * head.base[v].x > 0.0 && lid_lens(sx * head.base[v].x - EYE.0) > 0.0);
        let o = out.mesh.positions.len();
        let count = margin.len();
        for (i, &v) in margin.iter().enumerate() {
            let lens = lid_lens(sx * head.base[v].x - EYE.0);
            let root = p[v] + normals[v] * 0.0002;
            let dir = (normals[v] * 0.7 + Vector3::y() * 0.7).normalize();
            let tip = root + dir * (LASH_LENGTH * (0.35 + 0.65 * lens.sqrt()));
            let side = Vector3::x().cross(&dir).normalize();
            let u = i as f64 / (count - 1).max(1) as f64;
            out.mesh.positions.extend([root, tip]);
            out.normals.extend([side, side]);
            out.uvs.extend([[u, 1.0], [u, 0.0]]);
            let f = hinge_weights(p, &hinge, p[v].x);
            follow.extend([f, f]);
        }
        for i in 0..count.saturating_sub(1) {
            let (r0, t0, r1, t1) = (o + 2 * i, o + 2 * i + 1, o + 2 * i + 2, o + 2 * i + 3);
            let q = &out.mesh.positions;
            let facing = (q[r1] - q[r0])
                .cross(&(q[t1] - q[r0]))
                .dot(&out.normals[r0]);
            if facing >= 0.0 {
                out.mesh.triangles.extend([[r0, r1, t1], [r0, t1, t0]]);
            } else {
                out.mesh.triangles.extend([[r0, t1, r1], [r0, t0, t1]]);
            }
        }
    }
    out.normals = out.mesh.vertex_normals();
    (out, follow)
}

/// The two vertices of the polyline `row` (sorted by x, positions `p`) about `x` and their
/// linear weights there.
fn hinge_weights(p: &[Vector3<f64>], row: &[usize], x: f64) -> [(usize, f64); 2] {
    let i = (0..row.len() - 1)
        .find(|&i| p[row[i + 1]].x >= x)
        .unwrap_or(row.len() - 2);
    let (a, b) = (row[i], row[i + 1]);
    let f = ((x - p[a].x) / (p[b].x - p[a].x)).clamp(0.0, 1.0);
    [(a, 1.0 - f), (b, f)]
}

/// Every shape's deltas (m) of the lashes: each vertex takes the deltas of its `follow`
/// vertices of the head, weighted, from `head_shapes` (the head's shapes).
pub fn lash_shapes(follow: &[[(usize, f64); 2]], head_shapes: &Shapes) -> Shapes {
    head_shapes
        .iter()
        .map(|(name, d)| {
            let out = follow
                .iter()
                .map(|f| d[f[0].0] * f[0].1 + d[f[1].0] * f[1].1)
                .collect();
            (name.clone(), out)
        })
        .collect()
}

/// Heights of the body's cross-sections (m) and their half-width and half-depth (m), bottom
/// to top: hips, waist, chest, shoulders, then the neck, which ends inside the head's.
const BODY_SECTIONS: [(f64, f64, f64); 13] = [
    (0.90, 0.150, 0.100),
    (0.98, 0.170, 0.110),
    (1.06, 0.160, 0.100),
    (1.14, 0.140, 0.095),
    (1.22, 0.145, 0.100),
    (1.30, 0.160, 0.110),
    (1.37, 0.170, 0.110),
    (1.42, 0.180, 0.100),
    (1.46, 0.160, 0.085),
    (1.49, 0.075, 0.065),
    (1.52, 0.046, 0.042),
    (1.57, 0.042, 0.040),
    (1.62, 0.040, 0.038),
];

/// The stub body (m, standing on the origin, facing +Z): elliptic cross-sections from the hips
/// to the neck, closed at the bottom and open at the neck's top, 20 columns with the
/// texture's seam at the back (its column doubled); and each vertex's skin influences on
/// `joint_heights` (m, one per joint, bottom to top: each vertex blends the two joints whose
/// heights bracket it, linearly).
pub fn body(joint_heights: &[f64]) -> (Surface, Vec<Influences>) {
    let cols = 20;
    let mut pos = Vec::new();
    let mut uvs = Vec::new();
    let (y0, y1) = (BODY_SECTIONS[0].0, BODY_SECTIONS[BODY_SECTIONS.len() - 1].0);
    for &(y, rx, rz) in &BODY_SECTIONS {
        for j in 0..=cols {
            let ph = TAU * j as f64 / cols as f64;
            pos.push(Vector3::new(rx * ph.sin(), y, rz * ph.cos()));
            uvs.push([j as f64 / cols as f64, (y1 - y) / (y1 - y0)]);
        }
    }
    let bottom = pos.len();
    pos.push(Vector3::new(0.0, y0, 0.0));
    uvs.push([0.5, 1.0]);
    let id = |i: usize, j: usize| i * (cols + 1) + j;
    let mut tris = Vec::new();
    for j in 0..cols {
        tris.push([bottom, id(0, j), id(0, j + 1)]);
        for i in 0..BODY_SECTIONS.len() - 1 {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    // Columns run from +Z toward +X and sections upward, so these triangles face in: turn them.
    for t in &mut tris {
        t.swap(1, 2);
    }
    let mesh = TriMesh::new(pos, tris);
    let normals = welded_normals(&mesh);
    let infl = mesh
        .positions
        .iter()
        .map(|p| chain_influences(joint_heights, p.y))
        .collect();
    (Surface { mesh, normals, uvs }, infl)
}

/// Influences at height `y` (m) on a chain of joints at `heights` (m, increasing): the two
/// joints about `y` weighted linearly, the end joint alone beyond either end.
fn chain_influences(heights: &[f64], y: f64) -> Influences {
    let last = heights.len() - 1;
    if y <= heights[0] {
        return Influences::rigid(0);
    }
    for k in 0..last {
        if y < heights[k + 1] {
            let t = (y - heights[k]) / (heights[k + 1] - heights[k]);
            if t < 1e-9 {
                return Influences::rigid(k as u16);
            }
            return Influences {
                joints: [k as u16, k as u16 + 1, 0, 0],
                weights: [1.0 - t, t, 0.0, 0.0],
            };
        }
    }
    Influences::rigid(last as u16)
}

/// Unit vertex normals of `mesh` computed on it welded by position, so vertices doubled at a
/// seam get the same normal.
pub fn welded_normals(mesh: &TriMesh) -> Vec<Vector3<f64>> {
    let rep = weld_by_position(&mesh.positions, 1e-9);
    let tris = mesh.triangles.iter().map(|t| t.map(|v| rep[v])).collect();
    let n = TriMesh::new(mesh.positions.clone(), tris).vertex_normals();
    rep.iter().map(|&r| n[r]).collect()
}
