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

#[test]
fn svg_shapes_paths_and_transforms_give_their_areas() {
    use hexmesh::outline::outline_from_svg;
    let area = |svg: &str| outline_from_svg(svg.as_bytes(), "t.svg").unwrap().area();
    // A 2 x 1 rectangle drawn by a relative path, moved and scaled by groups.
    let a = area(
        r#"<svg><g transform="translate(5, 5)"><g transform="scale(2)">
           <path d="m 0,0 h 1 v 0.5 h -1 z"/></g></g></svg>"#,
    );
    assert!((a - 2.0).abs() < 1e-12, "{a}");
    // A ring: a circle with a circle inside (even-odd).
    let a = area(r#"<svg><circle cx="0" cy="0" r="2"/><circle cx="0" cy="0" r="1"/></svg>"#);
    let want = std::f64::consts::PI
        * 3.0
        * (64.0 / std::f64::consts::TAU * (std::f64::consts::TAU / 64.0).sin());
    assert!((a - want).abs() < 1e-9, "{a} vs {want}");
    // A polygon, rotated: area unchanged.
    let a = area(r#"<svg><polygon points="0,0 3,0 3,2 0,2" transform="rotate(30)"/></svg>"#);
    assert!((a - 6.0).abs() < 1e-12, "{a}");
    // A cubic curve closing a half-disc shape: between the chord's area 0
    // and the bounding box.
    let a = area(r#"<svg><path d="M 0 0 C 0 -1.3333 2 -1.3333 2 0 Z"/></svg>"#);
    assert!(a > 1.0 && a < 2.0, "{a}");
    // Errors name the file and the line.
    let e = outline_from_svg(
        b"<svg>\n<path d=\"M 0 0 A 1 1 0 0 1 2 0 Z\"/></svg>",
        "t.svg",
    )
    .unwrap_err()
    .to_string();
    assert!(e.starts_with("t.svg:2:") && e.contains("arc"), "{e}");
    let e = outline_from_svg(b"<svg><rect width='1' height='x'/></svg>", "t.svg")
        .unwrap_err()
        .to_string();
    assert!(e.contains("height"), "{e}");
    let e = outline_from_svg(b"<svg><g></svg>", "t.svg")
        .unwrap_err()
        .to_string();
    assert!(e.contains("malformed"), "{e}");
    let e = outline_from_svg(b"<svg></svg>", "t.svg")
        .unwrap_err()
        .to_string();
    assert!(e.contains("no cells") || e.contains("empty"), "{e}");
}

#[test]
fn a_planar_mesh_gives_its_boundary_loops_and_a_curved_one_is_refused() {
    use hexmesh::outline::outline_from_planar_mesh;
    // A 3 x 3 grid of unit squares in the plane z = 2, the middle one left
    // out: a square ring of area 8.
    let mut vertices = Vec::new();
    for j in 0..4 {
        for i in 0..4 {
            vertices.push([i as f64, j as f64, 2.0]);
        }
    }
    let mut triangles = Vec::new();
    for j in 0..3u32 {
        for i in 0..3u32 {
            if (i, j) == (1, 1) {
                continue;
            }
            let a = i + 4 * j;
            triangles.push([a, a + 1, a + 5]);
            triangles.push([a, a + 5, a + 4]);
        }
    }
    let mesh = hexmesh::TriMesh {
        vertices,
        triangles,
    };
    let outline = outline_from_planar_mesh(&mesh, "ring.obj").unwrap();
    assert_eq!(outline.polygons().len(), 2);
    assert!((outline.area() - 8.0).abs() < 1e-12, "{}", outline.area());
    let mut bent = mesh.clone();
    bent.vertices[5][2] = 2.5;
    let e = outline_from_planar_mesh(&bent, "bent.obj")
        .unwrap_err()
        .to_string();
    assert!(e.contains("bent.obj") && e.contains("not planar"), "{e}");
}
