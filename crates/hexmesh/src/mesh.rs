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
}
