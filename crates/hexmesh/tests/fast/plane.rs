//! Planar lattices: rectangles of any aspect ratio, outlines rasterized to
//! their area within one cell layer, boundaries closed and oriented.

use hexmesh::plane::{Outline, PlaneError, RectLattice, rasterize};

fn disc(r: f64, n: usize) -> Vec<[f64; 2]> {
    (0..n)
        .map(|i| {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            [r * a.cos(), r * a.sin()]
        })
        .collect()
}

#[test]
fn a_ring_rasterizes_to_its_area_within_a_cell_layer() {
    let ring = Outline::new(vec![disc(1.0, 720), disc(0.5, 720)]).unwrap();
    let exact = std::f64::consts::PI * (1.0 - 0.25);
    assert!((ring.area() - exact).abs() < 1e-4);
    let perimeter = std::f64::consts::TAU * 1.5;
    for cell in [[0.1, 0.05], [0.05, 0.05], [0.02, 0.08]] {
        let l = rasterize(&ring, cell).unwrap();
        let layer = perimeter * cell[0].max(cell[1]);
        assert!(
            (l.area() - exact).abs() < layer,
            "{cell:?}: {} vs {exact}",
            l.area()
        );
        // The boundary: every node on it has one edge in and one out.
        let edges = l.boundary_edges();
        let mut degree = std::collections::HashMap::new();
        for [a, b] in &edges {
            *degree.entry(*a).or_insert((0, 0)) = {
                let d = degree.get(a).copied().unwrap_or((0, 0));
                (d.0 + 1, d.1)
            };
            *degree.entry(*b).or_insert((0, 0)) = {
                let d = degree.get(b).copied().unwrap_or((0, 0));
                (d.0, d.1 + 1)
            };
        }
        assert!(degree.values().all(|(o, i)| o == i), "{cell:?}");
        // Oriented with the body on the left: the signed area the boundary
        // encloses is the lattice's.
        let nodes = l.nodes();
        let signed: f64 = edges
            .iter()
            .map(|[a, b]| {
                let (p, q) = (nodes[*a as usize], nodes[*b as usize]);
                0.5 * (p[0] * q[1] - q[0] * p[1])
            })
            .sum();
        assert!(
            (signed - l.area()).abs() < 1e-9 * l.area(),
            "{signed} vs {}",
            l.area()
        );
    }
}

#[test]
fn bad_outlines_and_sizes_are_errors() {
    assert_eq!(
        Outline::new(vec![vec![[0.0, 0.0], [1.0, 0.0]]]),
        Err(PlaneError::Degenerate(0, 2))
    );
    assert!(matches!(
        Outline::new(vec![vec![[0.0, 0.0], [1.0, f64::NAN], [0.0, 1.0]]]),
        Err(PlaneError::NonFinite(_))
    ));
    let square = Outline::new(vec![vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]]).unwrap();
    assert!(matches!(
        rasterize(&square, [0.0, 0.1]),
        Err(PlaneError::BadCellSize(_))
    ));
    // A cell larger than the shape: the one cell whose centre it holds.
    assert_eq!(rasterize(&square, [2.0, 2.0]).unwrap().num_cells(), 1);
    assert_eq!(
        RectLattice::from_occupancy([0.0; 2], [1.0; 2], [2, 2], &[false; 4]),
        Err(PlaneError::Empty)
    );
    assert!(matches!(
        rasterize(&square, [1e-6, 1e-6]),
        Err(PlaneError::GridTooLarge(..))
    ));
    assert!(RectLattice::block([0, 3], [1.0, 1.0], [0.0, 0.0]).is_err());
}
