//! The boundary of the chosen labels as a triangle surface, by surface nets
//! over the binary voxel mask.
//!
//! The dual cubes of the voxel grid have voxel centres at their corners. A
//! cube whose corners are partly chosen gets one vertex, at the mean of the
//! midpoints of its edges that cross the boundary; every pair of
//! neighbouring voxels of which exactly one is chosen gives a quad joining
//! the vertices of the four cubes around the segment between them, turned
//! so that its normal points out of the chosen voxels. Voxels outside the
//! image count as unchosen, so the surface is closed. Compared with
//! marching cubes, surface nets need no case table and give one vertex per
//! boundary cube (fewer, better-shaped triangles); where two chosen voxels
//! touch only along an edge or at a corner, the surface is pinched there
//! (not a 2-manifold), which rendering and embedding accept.
//!
//! Cost: one pass over the three voxel edges of every voxel in the chosen
//! labels' bounding box (plus one layer), and a hash map of the boundary
//! cubes only.

use std::collections::HashMap;

use super::resample::LabelChoice;
use super::{LabelImage, linear_det};
use crate::TriMesh;

/// The boundary of the voxels `choice` picks, mapped to world coordinates
/// by `voxel_to_world` (outward normals when the map keeps orientation;
/// flipped back when it mirrors).
pub(crate) fn label_surface(
    image: &LabelImage,
    choice: &LabelChoice<'_>,
    voxel_to_world: &[[f64; 4]; 3],
) -> TriMesh {
    let [nx, ny, nz] = image.dims.map(|d| d as i64);
    // Region: the chosen voxels' box and one layer around it.
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for (idx, &l) in image.labels.iter().enumerate() {
        if choice.contains(l) {
            let idx = idx as i64;
            let p = [idx % nx, (idx / nx) % ny, idx / (nx * ny)];
            for a in 0..3 {
                lo[a] = lo[a].min(p[a] - 1);
                hi[a] = hi[a].max(p[a] + 1);
            }
        }
    }
    let mut mesh = TriMesh {
        vertices: Vec::new(),
        triangles: Vec::new(),
    };
    if lo[0] > hi[0] {
        return mesh;
    }
    let inside = |p: [i64; 3]| -> bool {
        p[0] >= 0
            && p[1] >= 0
            && p[2] >= 0
            && p[0] < nx
            && p[1] < ny
            && p[2] < nz
            && choice.contains(image.labels[(p[0] + nx * (p[1] + ny * p[2])) as usize])
    };
    // Cube c spans voxels c .. c + 1 along every axis.
    let mut cube_vertex: HashMap<[i64; 3], u32> = HashMap::new();
    let mut vertex_of = |c: [i64; 3], vertices: &mut Vec<[f64; 3]>| -> u32 {
        *cube_vertex.entry(c).or_insert_with(|| {
            let mut sum = [0.0; 3];
            let mut n = 0.0;
            for axis in 0..3 {
                let (b, d) = ((axis + 1) % 3, (axis + 2) % 3);
                for s in 0..2 {
                    for t in 0..2 {
                        let mut p = c;
                        p[b] += s;
                        p[d] += t;
                        let mut q = p;
                        q[axis] += 1;
                        if inside(p) != inside(q) {
                            let mut mid = p.map(|v| v as f64);
                            mid[axis] += 0.5;
                            for k in 0..3 {
                                sum[k] += mid[k];
                            }
                            n += 1.0;
                        }
                    }
                }
            }
            vertices.push(sum.map(|v| v / n));
            (vertices.len() - 1) as u32
        })
    };
    for z in lo[2]..hi[2] + 1 {
        for y in lo[1]..hi[1] + 1 {
            for x in lo[0]..hi[0] + 1 {
                let p = [x, y, z];
                let here = inside(p);
                for axis in 0..3 {
                    let mut q = p;
                    q[axis] += 1;
                    if q[axis] > hi[axis] || here == inside(q) {
                        continue;
                    }
                    let (b, d) = ((axis + 1) % 3, (axis + 2) % 3);
                    let cube = |s: i64, t: i64| {
                        let mut c = p;
                        c[b] += s;
                        c[d] += t;
                        c
                    };
                    let quad = [
                        vertex_of(cube(-1, -1), &mut mesh.vertices),
                        vertex_of(cube(0, -1), &mut mesh.vertices),
                        vertex_of(cube(0, 0), &mut mesh.vertices),
                        vertex_of(cube(-1, 0), &mut mesh.vertices),
                    ];
                    // (b, d, axis) is right-handed: the quad's normal is +axis,
                    // outward when the chosen voxel is the lower one.
                    let [q0, q1, q2, q3] = if here {
                        quad
                    } else {
                        [quad[0], quad[3], quad[2], quad[1]]
                    };
                    mesh.triangles.push([q0, q1, q2]);
                    mesh.triangles.push([q0, q2, q3]);
                }
            }
        }
    }
    let a = voxel_to_world;
    let det = linear_det(a);
    for v in &mut mesh.vertices {
        let p = *v;
        *v = std::array::from_fn(|r| a[r][0] * p[0] + a[r][1] * p[1] + a[r][2] * p[2] + a[r][3]);
    }
    if det < 0.0 {
        for t in &mut mesh.triangles {
            t.swap(1, 2);
        }
    }
    mesh
}
