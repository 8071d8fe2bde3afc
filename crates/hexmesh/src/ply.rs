//! The PLY loader (Stanford polygon files: ASCII, binary little- and
//! big-endian), on the `ply-rs-bw` parser.
//!
//! Read: the `vertex` element's `x`, `y`, `z` (any scalar type) and the
//! `face` element's vertex list (`vertex_indices` or `vertex_index`, any
//! integer list type); polygons are triangulated as fans. Every other
//! element (edges, materials, ...) and property (normals, colours, texture
//! coordinates) is read past and ignored. Errors name the file and, where
//! the parser knows it, the line (for binary payloads: the header's line
//! count plus the element index, as `ply-rs-bw` counts them).
//!
//! ```
//! use hexmesh::load::MeshLoader;
//! use hexmesh::ply::PlyLoader;
//!
//! let text = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n\
//!             property float y\nproperty float z\nelement face 2\n\
//!             property list uchar int vertex_indices\nend_header\n\
//!             0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n3 0 2 1\n";
//! let mesh = PlyLoader.load(text.as_bytes(), "quad.ply").unwrap();
//! assert_eq!(mesh.vertices.len(), 4);
//! assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 2, 1]]);
//!
//! let lying = text.replace("element face 2", "element face 3");
//! let err = PlyLoader.load(lying.as_bytes(), "lying.ply").unwrap_err().to_string();
//! assert!(err.contains("lying.ply"), "{err}");
//! ```

use std::io::{BufReader, Cursor};
use std::path::PathBuf;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult, PropertyType};

use crate::TriMesh;
use crate::loader::{LoadError, MeshLoader, one_line};

/// The built-in PLY loader (ASCII, binary little-endian, binary big-endian).
#[derive(Debug, Clone, Copy, Default)]
pub struct PlyLoader;

/// A `vertex` element: its coordinates, as `f64` whatever the stored type.
#[derive(Default)]
struct Vertex {
    position: [f64; 3],
}

/// A `face` element: its vertex indices, as `i64` whatever the stored type
/// (so that negative or too-large values can be reported, not wrapped).
#[derive(Default)]
struct Face {
    indices: Vec<i64>,
}

/// Any other element: read past.
struct Ignored;

fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v.into(),
        Property::UChar(v) => v.into(),
        Property::Short(v) => v.into(),
        Property::UShort(v) => v.into(),
        Property::Int(v) => v.into(),
        Property::UInt(v) => v.into(),
        Property::Float(v) => v.into(),
        Property::Double(v) => v,
        _ => return None,
    })
}

fn int_list(p: Property) -> Option<Vec<i64>> {
    fn all<T: Into<i64>>(v: Vec<T>) -> Vec<i64> {
        v.into_iter().map(Into::into).collect()
    }
    Some(match p {
        Property::ListChar(v) => all(v),
        Property::ListUChar(v) => all(v),
        Property::ListShort(v) => all(v),
        Property::ListUShort(v) => all(v),
        Property::ListInt(v) => all(v),
        Property::ListUInt(v) => all(v),
        _ => return None,
    })
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Self::default()
    }
    fn set_property(&mut self, key: &str, property: Property) -> PropertyAccessResult {
        let axis = match key {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => return PropertyAccessResult::Ignored,
        };
        match scalar(&property) {
            Some(v) => {
                self.position[axis] = v;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }
}

impl PropertyAccess for Face {
    fn new() -> Self {
        Self::default()
    }
    fn set_property(&mut self, key: &str, property: Property) -> PropertyAccessResult {
        if !is_index_list(key) {
            return PropertyAccessResult::Ignored;
        }
        match int_list(property) {
            Some(v) => {
                self.indices = v;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }
}

impl PropertyAccess for Ignored {
    fn new() -> Self {
        Ignored
    }
}

/// The PLY parser's message as a sentence for the user: its nested
/// "String: '...' Error: ..." chains and grammar dumps (`expected one of
/// "\r\n", EOF, ...`) become what is wrong with which line.
fn plain_message(text: &str) -> String {
    let quoted = text
        .split_once("String: '")
        .and_then(|(_, rest)| rest.split_once('\''))
        .map(|(line, _)| line.trim().to_owned());
    match quoted {
        Some(line) if text.starts_with("Couldn't read element line") => format!(
            "the data line `{line}` does not hold the values the header declares \
             (as many numbers as the element's properties, each of its declared type)"
        ),
        Some(line) if text.starts_with("Invalid element") => format!(
            "the header line `{line}` is not `element NAME COUNT` with a whole count below 2^64"
        ),
        Some(line) if text.starts_with("Invalid property") => format!(
            "the header line `{line}` is not `property TYPE NAME` or \
             `property list COUNT_TYPE TYPE NAME` with PLY types"
        ),
        Some(line) => format!("the line `{line}` is not valid PLY here"),
        None => text
            .split_once(" Error: ")
            .map_or(text, |(first, _)| first)
            .to_owned(),
    }
}

fn is_index_list(name: &str) -> bool {
    name == "vertex_indices" || name == "vertex_index"
}

impl MeshLoader for PlyLoader {
    fn extensions(&self) -> &[&str] {
        &["ply"]
    }

    fn load(&self, bytes: &[u8], name: &str) -> Result<TriMesh, LoadError> {
        let parse = |line: Option<usize>, message: String| LoadError::Parse {
            file: PathBuf::from(name),
            line,
            message,
        };
        let from_parser = |e: ply_rs_bw::parser::ParseError| {
            // The parser's message starts with its own "Line N: " prefix.
            let text = e.to_string();
            let message = match e.line() {
                Some(_) => text
                    .split_once(": ")
                    .map_or(text.clone(), |(_, m)| m.to_owned()),
                None => text,
            };
            parse(e.line(), plain_message(&one_line(&message)))
        };
        if !bytes.starts_with(b"ply") {
            return Err(parse(
                Some(1),
                "a PLY file starts with the line \"ply\"".to_owned(),
            ));
        }
        let mut reader = Reader::new(BufReader::new(Cursor::new(bytes)));
        let header = Parser::<Vertex>::new()
            .read_header(&mut reader)
            .map_err(from_parser)?;
        let vertex_def = header
            .elements
            .get("vertex")
            .ok_or_else(|| parse(None, "the header declares no \"vertex\" element".to_owned()))?;
        for axis in ["x", "y", "z"] {
            match vertex_def.properties.get(axis).map(|p| &p.data_type) {
                Some(PropertyType::Scalar(_)) => {}
                Some(PropertyType::List(..)) => {
                    return Err(parse(
                        None,
                        format!("vertex property \"{axis}\" is a list; it must be a number"),
                    ));
                }
                None => {
                    return Err(parse(
                        None,
                        format!("the vertex element has no \"{axis}\" property"),
                    ));
                }
            }
        }
        if let Some(face_def) = header.elements.get("face") {
            let list = face_def
                .properties
                .iter()
                .find(|(k, _)| is_index_list(k))
                .map(|(_, p)| &p.data_type);
            match list {
                Some(PropertyType::List(_, item)) if !is_float(item) => {}
                Some(_) => {
                    return Err(parse(
                        None,
                        "the face element's vertex_indices must be a list of integers".to_owned(),
                    ));
                }
                None => {
                    return Err(parse(
                        None,
                        "the face element has no \"vertex_indices\" (or \"vertex_index\") list"
                            .to_owned(),
                    ));
                }
            }
        } else {
            return Err(parse(
                None,
                "the header declares no \"face\" element: a point cloud has no surface to voxelize"
                    .to_owned(),
            ));
        }

        let mut vertices: Vec<Vertex> = Vec::new();
        let mut faces: Vec<Face> = Vec::new();
        for (element_name, def) in &header.elements {
            match element_name.as_str() {
                "vertex" => {
                    vertices = Parser::<Vertex>::new()
                        .read_payload_for_element(&mut reader, def, &header)
                        .map_err(from_parser)?;
                }
                "face" => {
                    faces = Parser::<Face>::new()
                        .read_payload_for_element(&mut reader, def, &header)
                        .map_err(from_parser)?;
                }
                _ => {
                    Parser::<Ignored>::new()
                        .read_payload_for_element(&mut reader, def, &header)
                        .map_err(from_parser)?;
                }
            }
        }

        let mut mesh = TriMesh {
            vertices: vertices.iter().map(|v| v.position).collect(),
            triangles: Vec::with_capacity(faces.len()),
        };
        let n = mesh.vertices.len();
        for (f, face) in faces.iter().enumerate() {
            if face.indices.len() < 3 {
                // Points and edges stored as faces enclose nothing: skip them,
                // as the OBJ loader skips line elements.
                continue;
            }
            if let Some(&bad) = face.indices.iter().find(|&&i| i < 0) {
                return Err(parse(
                    None,
                    format!("face {f} has a negative vertex index {bad}"),
                ));
            }
            if let Some(&bad) = face.indices.iter().find(|&&i| i as u64 >= n as u64) {
                return Err(LoadError::IndexOutOfRange {
                    file: PathBuf::from(name),
                    triangle: f,
                    index: bad as u64,
                    vertices: n,
                });
            }
            let first = face.indices[0] as u32;
            for pair in face.indices[1..].windows(2) {
                mesh.triangles.push([first, pair[0] as u32, pair[1] as u32]);
            }
        }
        Ok(mesh)
    }
}

fn is_float(t: &ply_rs_bw::ply::ScalarType) -> bool {
    matches!(
        t,
        ply_rs_bw::ply::ScalarType::Float | ply_rs_bw::ply::ScalarType::Double
    )
}
