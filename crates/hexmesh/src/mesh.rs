//! Indexed triangle surfaces.

/// An indexed triangle surface: positions in `f64`, triangles as `u32` indices.
///
/// Triangles are counter-clockwise seen from outside when the mesh is
/// consistently oriented; nothing in this crate relies on it, since inside tests
/// must work for inconsistently oriented and open meshes too.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
}

/// An axis-aligned box `min ..= max` (m).
///
/// ```
/// use hexmesh::Aabb;
/// let b = Aabb::of_points([[0.0, 1.0, 2.0], [1.0, -1.0, 4.0]]).unwrap();
/// assert_eq!((b.min, b.max), ([0.0, -1.0, 2.0], [1.0, 1.0, 4.0]));
/// assert_eq!(b.extent(), [1.0, 2.0, 2.0]);
/// assert_eq!(b.diagonal(), 3.0);
/// assert_eq!(b.at_fraction([0.5, 0.5, 1.0]), [0.5, 0.0, 4.0]);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Minimum corner.
    pub min: [f64; 3],
    /// Maximum corner.
    pub max: [f64; 3],
}

impl Aabb {
    /// The smallest box holding every point; `None` without points.
    pub fn of_points<P: Into<[f64; 3]>>(points: impl IntoIterator<Item = P>) -> Option<Self> {
        let mut it = points.into_iter().map(Into::into);
        let first = it.next()?;
        let mut b = Aabb {
            min: first,
            max: first,
        };
        for p in it {
            b.min = std::array::from_fn(|k| b.min[k].min(p[k]));
            b.max = std::array::from_fn(|k| b.max[k].max(p[k]));
        }
        Some(b)
    }

    /// Edge lengths along x, y, z.
    pub fn extent(&self) -> [f64; 3] {
        std::array::from_fn(|k| self.max[k] - self.min[k])
    }

    /// Length of the diagonal.
    pub fn diagonal(&self) -> f64 {
        self.extent().iter().map(|e| e * e).sum::<f64>().sqrt()
    }

    /// The point at fractions `f` (0 = min, 1 = max) of the box along each axis.
    pub fn at_fraction(&self, f: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|k| self.min[k] + f[k] * (self.max[k] - self.min[k]))
    }
}

impl TriMesh {
    /// Axis-aligned bounding box of the vertices; `None` for a mesh without vertices.
    pub fn bounding_box(&self) -> Option<Aabb> {
        Aabb::of_points(self.vertices.iter().copied())
    }

    /// Signed enclosed volume by the divergence theorem (positive for a closed,
    /// outward-wound surface; meaningless for an open one).
    pub fn signed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize]);
                let cross = [
                    b[1] * c[2] - b[2] * c[1],
                    b[2] * c[0] - b[0] * c[2],
                    b[0] * c[1] - b[1] * c[0],
                ];
                (a[0] * cross[0] + a[1] * cross[1] + a[2] * cross[2]) / 6.0
            })
            .sum()
    }

    /// The same surface with no edge longer than `max_edge` (m): every
    /// triangle with a longer edge is split in four at its edges' midpoints
    /// (shared with its neighbours), until none is left. The triangles keep
    /// their winding and the surface its shape; a neighbour split only for
    /// its own long edges leaves a vertex on the middle of a shorter edge
    /// (no hole: the surface stays covered, which is what contact needs).
    /// A `max_edge` that is not positive and finite returns the mesh as it is.
    ///
    /// ```
    /// let cube = hexmesh::generate::box_mesh([0.0; 3], [1.0; 3]);
    /// let fine = cube.refined(0.3);
    /// assert!(fine.triangles.len() > 4 * cube.triangles.len());
    /// assert!((fine.signed_volume() - 1.0).abs() < 1e-12);
    /// ```
    pub fn refined(&self, max_edge: f64) -> TriMesh {
        let mut out = self.clone();
        if !(max_edge.is_finite() && max_edge > 0.0) {
            return out;
        }
        let long = |v: &[[f64; 3]], a: u32, b: u32| {
            let (p, q) = (v[a as usize], v[b as usize]);
            (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>() > max_edge * max_edge
        };
        loop {
            let mut midpoints: std::collections::HashMap<(u32, u32), u32> =
                std::collections::HashMap::new();
            let mut triangles = Vec::with_capacity(out.triangles.len());
            let mut split = false;
            for &[a, b, c] in &out.triangles {
                if !(long(&out.vertices, a, b)
                    || long(&out.vertices, b, c)
                    || long(&out.vertices, c, a))
                {
                    triangles.push([a, b, c]);
                    continue;
                }
                split = true;
                let mut mid = |p: u32, q: u32| {
                    *midpoints.entry((p.min(q), p.max(q))).or_insert_with(|| {
                        let (x, y) = (out.vertices[p as usize], out.vertices[q as usize]);
                        out.vertices
                            .push(std::array::from_fn(|k| 0.5 * (x[k] + y[k])));
                        (out.vertices.len() - 1) as u32
                    })
                };
                let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
                triangles.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
            }
            out.triangles = triangles;
            if !split {
                return out;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Refining keeps the enclosed volume and the area (the same surface),
    /// leaves no edge above the limit, and keeps every original vertex.
    #[test]
    fn refined_keeps_the_surface_and_shortens_every_edge() {
        let sphere = crate::generate::sphere(0.5, 1);
        let area = |m: &TriMesh| -> f64 {
            m.triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| m.vertices[i as usize]);
                    let u: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
                    let v: [f64; 3] = std::array::from_fn(|k| c[k] - a[k]);
                    let n = [
                        u[1] * v[2] - u[2] * v[1],
                        u[2] * v[0] - u[0] * v[2],
                        u[0] * v[1] - u[1] * v[0],
                    ];
                    0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
                })
                .sum()
        };
        for max_edge in [0.4, 0.1, 0.03] {
            let fine = sphere.refined(max_edge);
            assert_eq!(fine.vertices[..sphere.vertices.len()], sphere.vertices[..]);
            assert!((fine.signed_volume() - sphere.signed_volume()).abs() < 1e-12);
            assert!((area(&fine) - area(&sphere)).abs() < 1e-12 * area(&sphere));
            for t in &fine.triangles {
                for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                    let (p, q) = (fine.vertices[a as usize], fine.vertices[b as usize]);
                    let len = (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>().sqrt();
                    assert!(len <= max_edge, "an edge of {len} for {max_edge}");
                }
            }
        }
        assert_eq!(sphere.refined(f64::NAN), sphere);
    }
}
