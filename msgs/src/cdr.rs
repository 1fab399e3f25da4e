//! CDR (XCDR1, little endian) encoding as ROS 2 puts it on the wire and into bags.
//!
//! DDS samples and rosbag2 messages carry a 4-byte encapsulation header before the body:
//! `00 01 00 00` (CDR_LE) or `00 00 00 00` (CDR_BE); alignment is relative to the start
//! of the body. The `*_body` functions work without that header.

use byteorder::{BigEndian, LittleEndian};
use serde::{de::DeserializeOwned, Serialize};

/// The encapsulation header this crate writes: CDR, little endian, no options.
pub const ENCAPSULATION_CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

#[derive(Debug, thiserror::Error)]
pub enum CdrError {
    #[error("CDR encoding failed: {0}")]
    Encode(String),
    #[error("CDR decoding failed: {0}")]
    Decode(String),
    #[error("buffer of {0} bytes is too short for the 4-byte CDR encapsulation header")]
    NoHeader(usize),
    #[error(
        "unsupported CDR encapsulation {0:02x} {1:02x} (expected 00 01 CDR_LE or 00 00 CDR_BE)"
    )]
    Encapsulation(u8, u8),
}

/// Encode the body (little endian, no encapsulation header).
pub fn encode_body<T: Serialize>(value: &T) -> Result<Vec<u8>, CdrError> {
    cdr_encoding::to_vec::<T, LittleEndian>(value).map_err(|e| CdrError::Encode(e.to_string()))
}

/// Encode with the `00 01 00 00` encapsulation header (what a bag message holds).
pub fn encode<T: Serialize>(value: &T) -> Result<Vec<u8>, CdrError> {
    let mut out = Vec::with_capacity(64);
    out.extend_from_slice(&ENCAPSULATION_CDR_LE);
    cdr_encoding::to_writer::<T, LittleEndian, _>(&mut out, value)
        .map_err(|e| CdrError::Encode(e.to_string()))?;
    Ok(out)
}

/// Decode a little-endian body (no header). Trailing bytes (alignment padding a writer may
/// append) are ignored, as ROS 2 does.
pub fn decode_body<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, CdrError> {
    cdr_encoding::from_bytes::<T, LittleEndian>(bytes)
        .map(|(v, _)| v)
        .map_err(|e| CdrError::Decode(e.to_string()))
}

/// Decode a buffer that starts with the encapsulation header (LE or BE).
pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, CdrError> {
    if bytes.len() < 4 {
        return Err(CdrError::NoHeader(bytes.len()));
    }
    let body = &bytes[4..];
    match (bytes[0], bytes[1]) {
        (0x00, 0x01) => decode_body(body),
        (0x00, 0x00) => cdr_encoding::from_bytes::<T, BigEndian>(body)
            .map(|(v, _)| v)
            .map_err(|e| CdrError::Decode(e.to_string())),
        (a, b) => Err(CdrError::Encapsulation(a, b)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::*;

    fn roundtrip<T>(v: T)
    where
        T: Serialize + DeserializeOwned + PartialEq + std::fmt::Debug,
    {
        let body = encode_body(&v).unwrap();
        assert_eq!(decode_body::<T>(&body).unwrap(), v);
        let full = encode(&v).unwrap();
        assert_eq!(&full[..4], &ENCAPSULATION_CDR_LE);
        assert_eq!(&full[4..], &body[..]);
        assert_eq!(decode::<T>(&full).unwrap(), v);
    }

    #[test]
    fn twist_bytes_are_hand_checked() {
        let t = Twist {
            linear: Vector3 {
                x: 1.0,
                y: -0.5,
                z: 0.0,
            },
            angular: Vector3 {
                x: 0.0,
                y: 0.0,
                z: 2.0,
            },
        };
        // six float64, little endian, no padding: 48 bytes
        let mut expected = vec![0x00, 0x01, 0x00, 0x00];
        expected.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0xf0, 0x3f]); // 1.0
        expected.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0xe0, 0xbf]); // -0.5
        expected.extend_from_slice(&[0; 8]); // 0.0
        expected.extend_from_slice(&[0; 8]);
        expected.extend_from_slice(&[0; 8]);
        expected.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0x00, 0x40]); // 2.0
        assert_eq!(encode(&t).unwrap(), expected);
        assert_eq!(decode::<Twist>(&expected).unwrap(), t);
    }

    #[test]
    fn pose_stamped_bytes_are_hand_checked() {
        let p = PoseStamped {
            header: Header {
                stamp: Time {
                    sec: 5,
                    nanosec: 250_000_000,
                },
                frame_id: "map".into(),
            },
            pose: Pose {
                position: Point {
                    x: 0.5,
                    y: -1.0,
                    z: 0.0,
                },
                orientation: Quaternion::default(),
            },
        };
        let mut e = vec![0x00, 0x01, 0x00, 0x00];
        e.extend_from_slice(&[5, 0, 0, 0]); // sec int32
        e.extend_from_slice(&[0x80, 0xb2, 0xe6, 0x0e]); // nanosec 250_000_000
        e.extend_from_slice(&[4, 0, 0, 0]); // string length incl. NUL
        e.extend_from_slice(b"map\0"); // body offset now 16
                                       // float64 at offset 16: already 8-aligned, no padding
        e.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0xe0, 0x3f]); // x 0.5
        e.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0xf0, 0xbf]); // y -1.0
        e.extend_from_slice(&[0; 8]); // z
        e.extend_from_slice(&[0; 8]); // qx
        e.extend_from_slice(&[0; 8]); // qy
        e.extend_from_slice(&[0; 8]); // qz
        e.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0xf0, 0x3f]); // qw 1.0
        assert_eq!(encode(&p).unwrap(), e);
        assert_eq!(decode::<PoseStamped>(&e).unwrap(), p);
    }

    #[test]
    fn pose_stamped_frame_id_padding() {
        // frame_id "a": 4 + 4 + 4 + 2 = 14 bytes, then 2 bytes of padding to 16
        let p = PoseStamped::planar(Time::default(), "a", 1.0, 2.0);
        let b = encode_body(&p).unwrap();
        assert_eq!(&b[8..14], &[2, 0, 0, 0, b'a', 0]);
        assert_eq!(&b[14..16], &[0, 0]);
        assert_eq!(&b[16..24], &1.0f64.to_le_bytes());
        assert_eq!(b.len(), 16 + 7 * 8);
    }

    #[test]
    fn bool_and_clock_bytes() {
        assert_eq!(encode(&Bool { data: true }).unwrap(), vec![0, 1, 0, 0, 1]);
        let c = Clock {
            clock: Time { sec: 1, nanosec: 2 },
        };
        assert_eq!(
            encode(&c).unwrap(),
            vec![0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0]
        );
    }

    #[test]
    fn roundtrips() {
        roundtrip(Time {
            sec: -3,
            nanosec: 7,
        });
        roundtrip(Bool { data: true });
        roundtrip(ColorRGBA {
            r: 0.1,
            g: 0.2,
            b: 0.3,
            a: 1.0,
        });
        roundtrip(Twist::planar(0.5, -0.5));
        roundtrip(PoseStamped::planar(
            Time { sec: 9, nanosec: 1 },
            "map",
            -1.1,
            1.1,
        ));
        roundtrip(Clock {
            clock: Time {
                sec: 100,
                nanosec: 5,
            },
        });
        let marker = Marker {
            header: Header {
                stamp: Time { sec: 1, nanosec: 0 },
                frame_id: "map".into(),
            },
            ns: "robots".into(),
            id: 3,
            type_: Marker::SPHERE,
            action: Marker::ADD,
            pose: Pose::default(),
            scale: Vector3 {
                x: 0.1,
                y: 0.1,
                z: 0.1,
            },
            color: ColorRGBA {
                r: 1.0,
                g: 0.0,
                b: 0.0,
                a: 1.0,
            },
            lifetime: Duration {
                sec: 0,
                nanosec: 500,
            },
            frame_locked: true,
            points: vec![Point {
                x: 1.0,
                y: 2.0,
                z: 3.0,
            }],
            colors: vec![ColorRGBA::default(); 2],
            texture_resource: "".into(),
            texture: CompressedImage {
                header: Header::default(),
                format: "png".into(),
                data: vec![1, 2, 3],
            },
            uv_coordinates: vec![UVCoordinate { u: 0.5, v: 0.25 }],
            text: "r3".into(),
            mesh_resource: "".into(),
            mesh_file: MeshFile {
                filename: "x.stl".into(),
                data: vec![9; 5],
            },
            mesh_use_embedded_materials: true,
        };
        roundtrip(MarkerArray {
            markers: vec![marker.clone(), Marker::default(), marker],
        });
        roundtrip(DiagnosticArray {
            header: Header::default(),
            status: vec![DiagnosticStatus {
                level: DiagnosticStatus::WARN,
                name: "tending".into(),
                message: "ok".into(),
                hardware_id: "sim".into(),
                values: vec![
                    KeyValue {
                        key: "parts".into(),
                        value: "3".into(),
                    },
                    KeyValue {
                        key: "mu".into(),
                        value: "0.5".into(),
                    },
                ],
            }],
        });
    }

    #[test]
    fn short_and_bad_buffers_are_errors_not_panics() {
        let full = encode(&PoseStamped::planar(Time::default(), "map", 0.0, 0.0)).unwrap();
        for n in 0..full.len() {
            assert!(decode::<PoseStamped>(&full[..n]).is_err(), "len {n}");
        }
        assert!(matches!(
            decode::<Bool>(&[0x00, 0x07, 0, 0, 1]),
            Err(CdrError::Encapsulation(0, 7))
        ));
        // a huge sequence length must not allocate or panic
        let mut evil = vec![0, 1, 0, 0];
        evil.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode::<MarkerArray>(&evil).is_err());
    }

    #[test]
    fn big_endian_decodes() {
        let mut be = vec![0x00, 0x00, 0x00, 0x00];
        be.extend_from_slice(&1.5f64.to_be_bytes());
        be.extend_from_slice(&0.0f64.to_be_bytes());
        be.extend_from_slice(&0.0f64.to_be_bytes());
        let v: Vector3 = decode(&be).unwrap();
        assert_eq!(v.x, 1.5);
    }
}
