//! Helpers shared by the end-to-end tests (the tests live in `tests/tests/`).

use std::path::Path;

/// A closed, outward-wound box surface as OBJ text (8 vertices, 12 triangles).
pub fn box_obj(min: [f64; 3], max: [f64; 3]) -> String {
    let mut s = String::new();
    for k in 0..8 {
        let x = if k & 1 == 0 { min[0] } else { max[0] };
        let y = if k & 2 == 0 { min[1] } else { max[1] };
        let z = if k & 4 == 0 { min[2] } else { max[2] };
        s.push_str(&format!("v {x} {y} {z}\n"));
    }
    for q in [
        [1, 3, 4, 2],
        [5, 6, 8, 7],
        [1, 2, 6, 5],
        [3, 7, 8, 4],
        [1, 5, 7, 3],
        [2, 4, 8, 6],
    ] {
        s.push_str(&format!(
            "f {} {} {}\nf {} {} {}\n",
            q[0], q[1], q[2], q[0], q[2], q[3]
        ));
    }
    s
}

/// Writes `text` to `dir/name` and returns the path as a string.
pub fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write test input");
    p.to_str().expect("UTF-8 temp path").to_owned()
}
