//! The messages between the viewer's server and its page.
//!
//! Over one WebSocket per page:
//!
//! - server to page, text: [`SceneInfo`] (`"type": "scene"`) when the page
//!   connects and whenever the scene is rebuilt (reset), [`Status`]
//!   (`"type": "status"`) with every frame, and `{"type": "error", ...}`.
//! - server to page, binary (little-endian): the topology of the surfaces
//!   right after each scene message, then one frame message per displayed
//!   frame. Layouts in [`encode_topology`] and [`encode_frame`]; every
//!   array starts at a multiple of 4 bytes so that the page reads it as a
//!   `Float32Array` or `Uint32Array` without copying.
//! - page to server, text: [`ClientMessage`], JSON with a `"type"` tag.
//!   Messages are limited to [`MAX_CLIENT_MESSAGE_BYTES`]; one that does not
//!   parse or whose values are out of range ([`ClientMessage::validate`]) is
//!   logged and ignored.

use serde::{Deserialize, Serialize};

/// Largest text message a page may send (bytes).
pub const MAX_CLIENT_MESSAGE_BYTES: usize = 4096;

/// Tag of the binary topology message.
pub const TOPOLOGY_TAG: u32 = 0x4d53_5401;
/// Tag of the binary frame message.
pub const FRAME_TAG: u32 = 0x4d53_5402;

/// Largest coordinate a page may send (m): far beyond any body, small
/// enough that squares stay finite.
pub const MAX_COORDINATE: f64 = 1.0e6;

/// Slowest and fastest time scales (simulated seconds per wall second).
pub const TIME_SCALE_RANGE: (f64, f64) = (0.01, 10.0);

/// What a page asks of the server.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClientMessage {
    /// Run (live) or play the frames (replay).
    Play,
    /// Stop advancing.
    Pause,
    /// Advance by one frame and pause.
    Step,
    /// Live: rebuild the scene from its file (edits are picked up) and start
    /// from rest; replay: back to the first frame.
    Reset,
    /// Simulated seconds per wall second.
    TimeScale {
        /// The factor, within [`TIME_SCALE_RANGE`].
        value: f64,
    },
    /// Grab the body where the cursor hit it: the hit triangle of a
    /// displayed surface and the hit point on it (m).
    Pick {
        /// Surface index (as in [`SceneInfo::surfaces`]).
        surface: u32,
        /// Triangle of that surface.
        triangle: u32,
        /// The hit point (m).
        point: [f64; 3],
    },
    /// Move the grabbed nodes' target (m).
    Drag {
        /// Where the grab's centroid should go (m).
        target: [f64; 3],
    },
    /// Let go of the grab.
    Release,
    /// Put the poking sphere's centre here (m); it stays until moved or
    /// removed.
    Poke {
        /// The sphere's centre (m).
        centre: [f64; 3],
    },
    /// Take the poking sphere away.
    Unpoke,
    /// Replay: show frame `frame` (0-based) and pause.
    Seek {
        /// Frame index.
        frame: u32,
    },
}

/// Why a client message was ignored.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MessageError {
    /// Not JSON of a known message.
    #[error("unreadable message: {0}")]
    Unreadable(String),
    /// Longer than [`MAX_CLIENT_MESSAGE_BYTES`].
    #[error("message of {0} bytes, more than {MAX_CLIENT_MESSAGE_BYTES}")]
    TooLong(usize),
    /// A value is out of range.
    #[error("{0}")]
    OutOfRange(String),
}

fn point_ok(p: &[f64; 3]) -> bool {
    p.iter().all(|c| c.is_finite() && c.abs() <= MAX_COORDINATE)
}

impl ClientMessage {
    /// Parses and validates a text message from a page.
    pub fn parse(text: &str) -> Result<Self, MessageError> {
        if text.len() > MAX_CLIENT_MESSAGE_BYTES {
            return Err(MessageError::TooLong(text.len()));
        }
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| MessageError::Unreadable(e.to_string()))?;
        let keys = value.as_object().map_or(0, |o| o.len());
        let m: ClientMessage =
            serde_json::from_value(value).map_err(|e| MessageError::Unreadable(e.to_string()))?;
        // serde ignores unknown keys beside a unit variant's tag; every
        // field is required, so the round trip has exactly the keys it may.
        let known = serde_json::to_value(&m)
            .ok()
            .and_then(|v| v.as_object().map(|o| o.len()))
            .unwrap_or(0);
        if keys != known {
            return Err(MessageError::Unreadable(format!(
                "a {} message has {} keys where it takes {known}",
                m.name(),
                keys
            )));
        }
        m.validate()?;
        Ok(m)
    }

    /// The message's `type`.
    pub fn name(&self) -> &'static str {
        match self {
            ClientMessage::Play => "play",
            ClientMessage::Pause => "pause",
            ClientMessage::Step => "step",
            ClientMessage::Reset => "reset",
            ClientMessage::TimeScale { .. } => "time_scale",
            ClientMessage::Pick { .. } => "pick",
            ClientMessage::Drag { .. } => "drag",
            ClientMessage::Release => "release",
            ClientMessage::Poke { .. } => "poke",
            ClientMessage::Unpoke => "unpoke",
            ClientMessage::Seek { .. } => "seek",
        }
    }

    /// Checks the values: finite coordinates within [`MAX_COORDINATE`], a
    /// time scale within [`TIME_SCALE_RANGE`]. Indices are checked by the
    /// source that knows the surfaces.
    pub fn validate(&self) -> Result<(), MessageError> {
        match self {
            ClientMessage::TimeScale { value } => {
                let (lo, hi) = TIME_SCALE_RANGE;
                if !(value.is_finite() && (lo..=hi).contains(value)) {
                    return Err(MessageError::OutOfRange(format!(
                        "time scale {value} is outside [{lo}, {hi}]"
                    )));
                }
            }
            ClientMessage::Pick { point: p, .. }
            | ClientMessage::Drag { target: p }
            | ClientMessage::Poke { centre: p }
                if !point_ok(p) =>
            {
                return Err(MessageError::OutOfRange(format!(
                    "point {p:?} must be finite and within {MAX_COORDINATE} m"
                )));
            }
            _ => {}
        }
        Ok(())
    }
}

/// A surface the page can show.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurfaceInfo {
    /// `"surface"` (the input surface carried by the lattice) or `"skin"`
    /// (the lattice's boundary).
    pub name: String,
    /// Vertices.
    pub vertices: u32,
    /// Triangles.
    pub triangles: u32,
    /// Whether its frames carry the volume change J (false: the page
    /// greys the J colouring).
    pub has_jacobian: bool,
}

/// An obstacle as the page draws it (at its rest placement; offsets come
/// with each [`Status`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ObstacleDraw {
    /// A plane through `point` with outward `normal`.
    Plane {
        /// A point of the plane (m).
        point: [f64; 3],
        /// Unit outward normal.
        normal: [f64; 3],
    },
    /// A ball.
    Sphere {
        /// Centre (m).
        centre: [f64; 3],
        /// Radius (m).
        radius: f64,
    },
    /// An axis-aligned box.
    Box {
        /// Minimum corner (m).
        min: [f64; 3],
        /// Maximum corner (m).
        max: [f64; 3],
    },
    /// A capsule around the segment a b.
    Capsule {
        /// One end (m).
        a: [f64; 3],
        /// Other end (m).
        b: [f64; 3],
        /// Radius (m).
        radius: f64,
    },
    /// A mesh obstacle, drawn as its bounding box.
    Mesh {
        /// Minimum corner of its bounding box (m).
        min: [f64; 3],
        /// Maximum corner (m).
        max: [f64; 3],
    },
    /// A shape a program registered: the page does not draw it (it keeps
    /// its place, so that offsets stay aligned with the obstacles).
    Other {
        /// Its kind.
        shape: String,
    },
}

/// What the page is showing: sent on connect and after every rebuild.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneInfo {
    /// Always `"scene"`.
    #[serde(rename = "type")]
    pub kind: String,
    /// Counts up at every rebuild, so that a page tells frames of an old
    /// scene from the new one's.
    pub generation: u64,
    /// `"live"` or `"replay"`.
    pub mode: String,
    /// The scene file, bundled scene or run folder.
    pub name: String,
    /// Lattice cells (0 when the scene failed to build).
    pub cells: usize,
    /// Lattice nodes.
    pub nodes: usize,
    /// Cell edge (m).
    pub cell_size: f64,
    /// Bounding box of the body at rest (m): min, max.
    pub bounds: [[f64; 3]; 2],
    /// The surfaces, in the order of the binary messages.
    pub surfaces: Vec<SurfaceInfo>,
    /// The scene's obstacles.
    pub obstacles: Vec<ObstacleDraw>,
    /// Radius of the poking sphere (m).
    pub poke_radius: f64,
    /// Replay: the frames' times (s); empty when live.
    pub frame_times: Vec<f64>,
    /// Why the scene could not be built or run, for the page to show.
    pub error: Option<String>,
}

impl SceneInfo {
    /// The message of a scene that could not be built or read: no body,
    /// only the error for the page to show.
    pub fn failed(generation: u64, mode: &str, name: String, error: String) -> Self {
        SceneInfo {
            kind: "scene".into(),
            generation,
            mode: mode.into(),
            name,
            cells: 0,
            nodes: 0,
            cell_size: 0.0,
            bounds: [[0.0; 3]; 2],
            surfaces: Vec::new(),
            obstacles: Vec::new(),
            poke_radius: 0.0,
            frame_times: Vec::new(),
            error: Some(error),
        }
    }
}

/// The state that comes with every frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Status {
    /// Always `"status"`.
    #[serde(rename = "type")]
    pub kind: String,
    /// The scene generation this frame belongs to.
    pub generation: u64,
    /// Frame number since the scene was built.
    pub seq: u64,
    /// Simulated time (s).
    pub time: f64,
    /// Whether time advances.
    pub playing: bool,
    /// Simulated seconds per wall second asked for.
    pub time_scale: f64,
    /// Simulated seconds per wall second achieved over the last second.
    pub real_time_factor: f64,
    /// CPU milliseconds of the last frame's simulation (live).
    pub frame_ms: f64,
    /// Explicit sub-steps of the last frame (live).
    pub substeps: u32,
    /// Replay: the frame shown.
    pub frame: u32,
    /// The grab's target (m), while the body is held.
    pub grab_target: Option<[f64; 3]>,
    /// The centroid of the grabbed nodes now (m), while the body is held.
    pub grab_centroid: Option<[f64; 3]>,
    /// The poking sphere's centre (m), while it is out.
    pub poke_centre: Option<[f64; 3]>,
    /// Offset of each scene obstacle from its rest placement (m).
    pub obstacle_offsets: Vec<[f64; 3]>,
    /// Largest node displacement (m).
    pub max_displacement: f64,
    /// A solver error that stopped the run, for the page to show.
    pub error: Option<String>,
}

/// One surface's share of a frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SurfaceFrame {
    /// Vertex positions (m).
    pub positions: Vec<[f32; 3]>,
    /// Displacement magnitude per vertex (m).
    pub displacement: Vec<f32>,
    /// Volume change J per vertex (1 where unknown).
    pub jacobian: Vec<f32>,
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_f32s(out: &mut Vec<u8>, v: impl Iterator<Item = f32>) {
    for x in v {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

/// The topology message: `u32 tag, u32 surfaces`, then per surface
/// `u32 triangles` and `3 * triangles` `u32` vertex indices.
pub fn encode_topology(surfaces: &[&[[u32; 3]]]) -> Vec<u8> {
    let total: usize = surfaces.iter().map(|t| 4 + 12 * t.len()).sum();
    let mut out = Vec::with_capacity(8 + total);
    put_u32(&mut out, TOPOLOGY_TAG);
    put_u32(&mut out, surfaces.len() as u32);
    for tris in surfaces {
        put_u32(&mut out, tris.len() as u32);
        for t in tris.iter() {
            for &i in t {
                put_u32(&mut out, i);
            }
        }
    }
    out
}

/// The frame message: `u32 tag, u32 surfaces, u64 generation, u64 seq,
/// f64 time`, then per surface `u32 vertices`, `3 * vertices` `f32`
/// positions, `vertices` `f32` displacement magnitudes and `vertices`
/// `f32` values of J.
pub fn encode_frame(generation: u64, seq: u64, time: f64, surfaces: &[SurfaceFrame]) -> Vec<u8> {
    let total: usize = surfaces.iter().map(|s| 4 + 20 * s.positions.len()).sum();
    let mut out = Vec::with_capacity(32 + total);
    put_u32(&mut out, FRAME_TAG);
    put_u32(&mut out, surfaces.len() as u32);
    out.extend_from_slice(&generation.to_le_bytes());
    out.extend_from_slice(&seq.to_le_bytes());
    out.extend_from_slice(&time.to_le_bytes());
    for s in surfaces {
        put_u32(&mut out, s.positions.len() as u32);
        put_f32s(&mut out, s.positions.iter().flatten().copied());
        put_f32s(&mut out, s.displacement.iter().copied());
        put_f32s(&mut out, s.jacobian.iter().copied());
    }
    out
}

/// A decoded frame message (what the page reads), for tests and tools.
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedFrame {
    /// Scene generation.
    pub generation: u64,
    /// Frame number.
    pub seq: u64,
    /// Simulated time (s).
    pub time: f64,
    /// The surfaces.
    pub surfaces: Vec<SurfaceFrame>,
}

struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let end = self.at.checked_add(n)?;
        let s = self.bytes.get(self.at..end)?;
        self.at = end;
        Some(s)
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn f32s(&mut self, n: usize) -> Option<Vec<f32>> {
        let s = self.take(n.checked_mul(4)?)?;
        Some(
            s.chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        )
    }
}

/// Reads a frame message; `None` if it is not one or is cut short.
pub fn decode_frame(bytes: &[u8]) -> Option<DecodedFrame> {
    let mut c = Cursor { bytes, at: 0 };
    if c.u32()? != FRAME_TAG {
        return None;
    }
    let n = c.u32()?;
    let generation = c.u64()?;
    let seq = c.u64()?;
    let time = c.f64()?;
    let mut surfaces = Vec::new();
    for _ in 0..n {
        let v = c.u32()? as usize;
        let flat = c.f32s(v.checked_mul(3)?)?;
        surfaces.push(SurfaceFrame {
            positions: flat.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect(),
            displacement: c.f32s(v)?,
            jacobian: c.f32s(v)?,
        });
    }
    (c.at == bytes.len()).then_some(DecodedFrame {
        generation,
        seq,
        time,
        surfaces,
    })
}

/// Reads a topology message; `None` if it is not one or is cut short.
pub fn decode_topology(bytes: &[u8]) -> Option<Vec<Vec<[u32; 3]>>> {
    let mut c = Cursor { bytes, at: 0 };
    if c.u32()? != TOPOLOGY_TAG {
        return None;
    }
    let n = c.u32()?;
    let mut out = Vec::new();
    for _ in 0..n {
        let t = c.u32()? as usize;
        let mut tris = Vec::with_capacity(t.min(bytes.len() / 12));
        for _ in 0..t {
            tris.push([c.u32()?, c.u32()?, c.u32()?]);
        }
        out.push(tris);
    }
    (c.at == bytes.len()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_and_topology_round_trip() {
        let s = SurfaceFrame {
            positions: vec![[0.0, 1.5, -2.0], [3.25, f32::MIN_POSITIVE, 7.0]],
            displacement: vec![0.5, 0.25],
            jacobian: vec![1.0, 0.9],
        };
        let bytes = encode_frame(3, 17, 0.125, &[s.clone(), SurfaceFrame::default()]);
        let d = decode_frame(&bytes).unwrap();
        assert_eq!((d.generation, d.seq, d.time), (3, 17, 0.125));
        assert_eq!(d.surfaces, vec![s, SurfaceFrame::default()]);
        assert!(decode_frame(&bytes[..bytes.len() - 1]).is_none());
        let tris = vec![[0, 1, 2], [2, 1, 3]];
        let t = encode_topology(&[&tris, &[]]);
        assert_eq!(decode_topology(&t).unwrap(), vec![tris, vec![]]);
        assert!(decode_topology(&bytes).is_none());
        // Arrays start at multiples of 4 bytes (a Float32Array view needs it).
        assert_eq!(32 % 4, 0);
    }

    #[test]
    fn bad_messages_are_refused() {
        for bad in [
            "",
            "{",
            "[]",
            r#"{"type":"nope"}"#,
            r#"{"type":"play","extra":1}"#,
            r#"{"type":"time_scale","value":0}"#,
            r#"{"type":"time_scale","value":1e9}"#,
            r#"{"type":"drag","target":[0,0]}"#,
            r#"{"type":"drag","target":[0,0,1e300]}"#,
            r#"{"type":"pick","surface":0,"triangle":-1,"point":[0,0,0]}"#,
            r#"{"type":"seek","frame":1.5}"#,
        ] {
            assert!(ClientMessage::parse(bad).is_err(), "{bad}");
        }
        let long = format!(r#"{{"type":"play","pad":"{}"}}"#, "x".repeat(5000));
        assert!(matches!(
            ClientMessage::parse(&long),
            Err(MessageError::TooLong(_))
        ));
        assert_eq!(
            ClientMessage::parse(r#"{"type":"drag","target":[0.1,0,-2]}"#).unwrap(),
            ClientMessage::Drag {
                target: [0.1, 0.0, -2.0]
            }
        );
        assert_eq!(
            ClientMessage::parse(r#"{"type":"seek","frame":4}"#).unwrap(),
            ClientMessage::Seek { frame: 4 }
        );
    }
}
