//! Lattice construction: element counts, node sharing, superimposed elements, embedding,
//! bone nodes, settings validation.
#![allow(clippy::needless_range_loop)]

mod lattice_support;

use furrow::lattice::{ElementKind, ElementOrder, Lattice, LatticeError, LatticeSettings};
use lattice_support::{box_mesh, merge, slit_sheet};
use nalgebra::Vector3;
use std::collections::HashSet;

type V = Vector3<f64>;

fn settings(h: f64, order: ElementOrder) -> LatticeSettings {
    LatticeSettings {
        cell_size: Some(h),
        order,
        ..Default::default()
    }
}

/// A closed box of 4 × 3 × 2 cells gets exactly one element per cell, and all of them share
/// nodes as one body: (4+2)(3+2)(2+2) quadratic nodes, (4+1)(3+1)(2+1) trilinear.
#[test]
fn one_body_fills_its_cells_and_shares_all_nodes() {
    let mesh = box_mesh(V::zeros(), V::new(0.4, 0.3, 0.2), 8);
    for (order, nodes) in [
        (ElementOrder::Quadratic, 6 * 5 * 4),
        (ElementOrder::Trilinear, 5 * 4 * 3),
    ] {
        let lat = Lattice::build(&mesh, &settings(0.1, order)).unwrap();
        assert!(lat.closed);
        assert_eq!(lat.dims, [4, 3, 2]);
        assert_eq!(lat.elements.len(), 24, "{order:?}");
        assert_eq!(lat.node_count(), nodes, "{order:?}");
        assert_eq!(lat.pinned_count(), 0);
        // Rest control points reproduce the geometry: x = B q_rest exactly.
        let x = lat.embed(&lat.rest_flat());
        for (p, e) in mesh.positions.iter().zip(&x) {
            assert!((p - e).norm() < 1e-12, "{p} vs {e}");
        }
        // Rows of B sum to one.
        let mut rows = vec![0.0; mesh.positions.len()];
        for (v, _, w) in lat.embedding_triplets() {
            rows[v] += w;
        }
        assert!(rows.iter().all(|s| (s - 1.0).abs() < 1e-13));
        let b = lat.embedding().unwrap();
        assert_eq!(
            (b.nrows(), b.ncols()),
            (mesh.positions.len(), lat.node_count())
        );
    }
}

/// A closed box 4 × 4 × 4 cells has interior cells without surface: they become volume
/// elements and the body still has one element per cell.
#[test]
fn interior_cells_become_volume_elements() {
    let mesh = box_mesh(V::zeros(), V::repeat(0.4), 4);
    let lat = Lattice::build(&mesh, &settings(0.1, ElementOrder::Quadratic)).unwrap();
    assert_eq!(lat.elements.len(), 64);
    let vol = lat
        .elements
        .iter()
        .filter(|e| e.kind == ElementKind::Volume)
        .count();
    assert_eq!(vol, 8);
    assert_eq!(lat.node_count(), 6 * 6 * 6);
}

/// Two boxes 1 cm apart inside shared cells: the shared cells hold two superimposed
/// elements, and the two bodies have disjoint node sets.
#[test]
fn separate_bodies_in_shared_cells_get_superimposed_elements() {
    let a = box_mesh(V::new(0.0, 0.0, 0.0), V::new(0.25, 0.2, 0.2), 5);
    let b = box_mesh(V::new(0.26, 0.0, 0.0), V::new(0.5, 0.2, 0.2), 5);
    let mesh = merge(&a, &b);
    let lat = Lattice::build(&mesh, &settings(0.1, ElementOrder::Quadratic)).unwrap();
    // Cells along x: [0,.1] [.1,.2] [.2,.3] [.3,.4] [.4,.5]; the gap lies in the third.
    let shared: Vec<_> = lat.elements.iter().filter(|e| e.cell[0] == 2).collect();
    assert_eq!(
        shared.len(),
        2 * 2 * 2,
        "two superimposed elements per shared cell"
    );
    let nodes_of = |vs: std::ops::Range<usize>| -> HashSet<usize> {
        vs.flat_map(|v| {
            lat.weights(&lat.vertex_points[v])
                .into_iter()
                .map(|(n, _)| n)
        })
        .collect()
    };
    let na = a.positions.len();
    let sa = nodes_of(0..na);
    let sb = nodes_of(na..mesh.positions.len());
    assert!(
        sa.is_disjoint(&sb),
        "bodies share {} nodes",
        sa.intersection(&sb).count()
    );
    // Every element belongs to exactly one body: its node set meets only one side.
    let x = lat.embed(&lat.rest_flat());
    for (p, e) in mesh.positions.iter().zip(&x) {
        assert!((p - e).norm() < 1e-12);
    }
    assert_eq!(lat.elements.len(), 5 * 2 * 2 + 4);
}

/// Trilinear lattices share one node layer (4 nodes) across faces, quadratic two (18).
#[test]
fn face_neighbours_share_18_quadratic_or_4_trilinear_nodes() {
    let mesh = box_mesh(V::zeros(), V::new(0.2, 0.1, 0.1), 2);
    for (order, shared) in [(ElementOrder::Quadratic, 18), (ElementOrder::Trilinear, 4)] {
        let lat = Lattice::build(&mesh, &settings(0.1, order)).unwrap();
        assert_eq!(lat.elements.len(), 2);
        let a: HashSet<_> = lat.elements[0].nodes.iter().collect();
        let b: HashSet<_> = lat.elements[1].nodes.iter().collect();
        assert_eq!(a.intersection(&b).count(), shared, "{order:?}");
    }
}

/// An open sheet with a mouth slit: the cells on the slit hold separate upper and lower lip
/// elements; flesh reaches `depth` behind; nodes deeper are bone.
#[test]
fn slit_sheet_lips_get_separate_elements_and_bone_behind() {
    let (mesh, upper, lower) = slit_sheet(0.05, 0.005, 0.025);
    let s = LatticeSettings {
        cell_size: Some(0.0125),
        depth: Some(0.02),
        ..Default::default()
    };
    let lat = Lattice::build(&mesh, &s).unwrap();
    assert!(!lat.closed);
    // Same cell, different elements, on every slit vertex pair away from the corners.
    let mut distinct = 0;
    for (&u, &l) in upper.iter().zip(&lower) {
        let (eu, el) = (lat.vertex_points[u].element, lat.vertex_points[l].element);
        assert_eq!(lat.elements[eu].cell, lat.elements[el].cell);
        if eu != el {
            distinct += 1;
        }
    }
    assert!(
        distinct >= upper.len() - 2,
        "{distinct} of {} slit pairs separated",
        upper.len()
    );
    // Bone: every pinned node is behind the sheet deeper than the depth; no node in front or
    // within the flesh is pinned.
    assert!(lat.pinned_count() > 0);
    for (p, &pin) in lat.rest.iter().zip(&lat.pinned) {
        let inside_sheet = p.x.abs() < 0.05 && p.y.abs() < 0.05;
        if inside_sheet {
            assert_eq!(pin, p.z < -0.02, "node at {p} pinned={pin}");
        }
    }
    // No element lies entirely in front of the sheet or deeper than depth + a cell.
    for e in 0..lat.elements.len() {
        let o = lat.cell_origin(e);
        assert!(
            o.z < 0.0 + 1e-12 && o.z + lat.cell_size > -0.02 - 1e-12,
            "cell at z {}",
            o.z
        );
    }
    let x = lat.embed(&lat.rest_flat());
    for (p, e) in mesh.positions.iter().zip(&x) {
        assert!((p - e).norm() < 1e-12);
    }
}

#[test]
fn settings_errors_name_the_field() {
    let mesh = box_mesh(V::zeros(), V::repeat(0.1), 1);
    let cases = [
        (
            LatticeSettings {
                cell_size: Some(-1.0),
                ..Default::default()
            },
            "cell_size",
        ),
        (
            LatticeSettings {
                target_cells: Some(0),
                ..Default::default()
            },
            "target_cells",
        ),
        (
            LatticeSettings {
                depth: Some(f64::NAN),
                ..Default::default()
            },
            "depth",
        ),
        (
            LatticeSettings {
                cell_size: Some(0.1),
                target_cells: Some(8),
                ..Default::default()
            },
            "target_cells",
        ),
    ];
    for (s, field) in cases {
        match Lattice::build(&mesh, &s) {
            Err(LatticeError::Settings { field: f, .. }) => assert_eq!(f, field),
            other => panic!("expected a settings error for {field}, got {other:?}"),
        }
    }
    let tiny = LatticeSettings {
        cell_size: Some(1e-6),
        ..Default::default()
    };
    assert!(matches!(
        Lattice::build(&mesh, &tiny),
        Err(LatticeError::TooManyCells { .. })
    ));
    let lat = Lattice::build(
        &mesh,
        &LatticeSettings {
            target_cells: Some(27),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(lat.dims, [3, 3, 3]);
}
