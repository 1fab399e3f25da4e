//! Bag writer/reader round trip, chunking, metadata.yaml, and recovery of cut files.

use std::path::{Path, PathBuf};

use bag::{recover, BagMetadata, BagReader, BagWriter, WriterOptions};
use msgs::{schema, Bool, Clock, PoseStamped, Profile, Time};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bag-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

const T0: u64 = 1_700_000_000_000_000_000;
const DT: u64 = 100_000_000; // 10 Hz

/// Writes `steps` steps of a small fleet: /clock, two robots' pose + has_part, one
/// machine's pose and part_ready. Returns the (topic, time, bytes) written, in order.
fn write_fleet(w: &mut BagWriter, steps: u64) -> Vec<(String, u64, Vec<u8>)> {
    w.add_topic("/clock", &schema::CLOCK, &Profile::Clock.offered_qos_yaml())
        .unwrap();
    for r in ["robot_0", "robot_1"] {
        w.add_topic(
            &format!("/{r}/pose"),
            &schema::POSE_STAMPED,
            &Profile::RobotStream.offered_qos_yaml(),
        )
        .unwrap();
        w.add_topic(
            &format!("/{r}/has_part"),
            &schema::BOOL,
            &Profile::RobotStream.offered_qos_yaml(),
        )
        .unwrap();
    }
    w.add_topic(
        "/machine_0/pose",
        &schema::POSE_STAMPED,
        &Profile::LatchedPose.offered_qos_yaml(),
    )
    .unwrap();
    w.add_topic(
        "/machine_0/part_ready",
        &schema::BOOL,
        &Profile::PartReady.offered_qos_yaml(),
    )
    .unwrap();
    let mut out = Vec::new();
    let mut put = |w: &mut BagWriter, topic: &str, t: u64, bytes: Vec<u8>| {
        w.write(topic, t, &bytes).unwrap();
        out.push((topic.to_string(), t, bytes));
    };
    let m = msgs::cdr::encode(&PoseStamped::planar(Time::default(), "map", 0.5, 0.5)).unwrap();
    put(w, "/machine_0/pose", T0, m);
    for k in 0..steps {
        let t = T0 + 10 + k * DT;
        let stamp = Time::from_secs_f64(k as f64 * 0.1);
        put(
            w,
            "/clock",
            t,
            msgs::cdr::encode(&Clock { clock: stamp }).unwrap(),
        );
        for (i, r) in ["robot_0", "robot_1"].iter().enumerate() {
            let p = PoseStamped::planar(stamp, "map", k as f64 * 0.01, i as f64);
            put(
                w,
                &format!("/{r}/pose"),
                t + 1,
                msgs::cdr::encode(&p).unwrap(),
            );
            let b = Bool {
                data: (k / 7 + i as u64) % 2 == 1,
            };
            put(
                w,
                &format!("/{r}/has_part"),
                t + 2,
                msgs::cdr::encode(&b).unwrap(),
            );
        }
        if k % 5 == 0 {
            let b = Bool { data: k % 10 == 0 };
            put(
                w,
                "/machine_0/part_ready",
                t + 3,
                msgs::cdr::encode(&b).unwrap(),
            );
        }
    }
    out
}

fn assert_same(r: &BagReader, expected: &[(String, u64, Vec<u8>)]) {
    assert_eq!(r.messages.len(), expected.len());
    for (m, (topic, t, bytes)) in r.messages.iter().zip(expected) {
        assert_eq!(&r.topic(m).name, topic);
        assert_eq!(m.log_time, *t);
        assert_eq!(m.publish_time, *t);
        assert_eq!(&m.data, bytes);
    }
}

#[test]
fn write_read_roundtrip_file_and_dir() {
    let dir = tmp("roundtrip");
    let mut w = BagWriter::create(&dir).unwrap();
    let expected = write_fleet(&mut w, 50);
    let meta = w.finish().unwrap();
    assert_eq!(meta.message_count, expected.len() as u64);

    for path in [dir.clone(), dir.join(bag::mcap_file_name(&dir))] {
        let r = BagReader::open_strict(&path).unwrap();
        assert!(r.complete, "{}", path.display());
        assert_same(&r, &expected);
        let pose = r.topics.iter().find(|t| t.name == "/robot_1/pose").unwrap();
        assert_eq!(pose.type_name, "geometry_msgs/msg/PoseStamped");
        assert_eq!(pose.schema_text, msgs::schema_text(&schema::POSE_STAMPED));
        assert_eq!(pose.qos_yaml, Profile::RobotStream.offered_qos_yaml());
        assert_eq!(pose.message_count, 50);
    }
    let r = BagReader::open(&dir).unwrap();
    let poses = r.decode_topic::<PoseStamped>("/robot_0/pose").unwrap();
    assert_eq!(poses.len(), 50);
    assert!((poses[10].1.pose.position.x - 0.1).abs() < 1e-12);

    // Summary: one schema per type, one channel per topic, Statistics.
    let bytes = std::fs::read(dir.join(bag::mcap_file_name(&dir))).unwrap();
    let s = mcap::Summary::read(&bytes).unwrap().unwrap();
    let stats = s.stats.unwrap();
    assert_eq!(stats.message_count, expected.len() as u64);
    assert_eq!(stats.schema_count, 3); // Clock, PoseStamped, Bool
    assert_eq!(stats.channel_count, 7);
    assert_eq!(stats.message_start_time, T0);
    assert_eq!(stats.message_end_time, T0 + 10 + 49 * DT + 2);
    assert!(!s.chunk_indexes.is_empty());
    for c in s.channels.values() {
        assert_eq!(c.message_encoding, "cdr");
        let sch = c.schema.as_ref().unwrap();
        assert_eq!(sch.encoding, "ros2msg");
        assert!(c.metadata.contains_key("offered_qos_profiles"));
    }

    // metadata.yaml agrees with the file, QoS string identical to the channel's.
    let m = BagMetadata::read_from(&dir).unwrap();
    assert_eq!(m.message_count, expected.len() as u64);
    assert_eq!(m.time_range, Some((T0, T0 + 10 + 49 * DT + 2)));
    for t in &m.topics {
        let rt = r.topics.iter().find(|x| x.name == t.name).unwrap();
        assert_eq!(t.qos_yaml, rt.qos_yaml);
        assert_eq!(t.type_name, rt.type_name);
        assert_eq!(t.message_count, rt.message_count);
    }
    let text = std::fs::read_to_string(dir.join("metadata.yaml")).unwrap();
    assert!(text.contains("version: 9"));
    assert!(text.contains("storage_identifier: mcap"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn chunks_are_bounded_in_time_and_size() {
    let dir = tmp("chunks");
    // 20 s of data at 10 Hz: chunks close every second of log time.
    let mut w = BagWriter::create(&dir).unwrap();
    write_fleet(&mut w, 200);
    w.finish().unwrap();
    let bytes = std::fs::read(dir.join(bag::mcap_file_name(&dir))).unwrap();
    let s = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(
        s.chunk_indexes.len() >= 19,
        "{} chunks",
        s.chunk_indexes.len()
    );
    for c in &s.chunk_indexes {
        assert!(c.message_end_time - c.message_start_time < 1_000_000_000);
    }
    let _ = std::fs::remove_dir_all(&dir);

    // Size bound: 2 KiB chunks.
    let dir = tmp("chunks-size");
    let mut w = BagWriter::create_with(
        &dir,
        WriterOptions {
            chunk_bytes: 2048,
            ..Default::default()
        },
    )
    .unwrap();
    write_fleet(&mut w, 100);
    w.finish().unwrap();
    let bytes = std::fs::read(dir.join(bag::mcap_file_name(&dir))).unwrap();
    let s = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(s.chunk_indexes.len() > 10);
    // (the first chunk also holds the schema and channel records)
    for c in &s.chunk_indexes[1..] {
        assert!(c.uncompressed_size <= 2048 + 200, "{}", c.uncompressed_size);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn drop_finalizes_and_existing_dir_is_refused() {
    let dir = tmp("drop");
    {
        let mut w = BagWriter::create(&dir).unwrap();
        write_fleet(&mut w, 3);
    }
    let r = BagReader::open_strict(&dir).unwrap();
    assert_eq!(r.messages.len(), 1 + 3 * 5 + 1);
    assert!(BagWriter::create(&dir).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_is_refused() {
    let dir = tmp("bad");
    let mut w = BagWriter::create(&dir).unwrap();
    w.add_topic("/x/has_part", &schema::BOOL, "q").unwrap();
    assert!(w.write("/x/has_part", 1, &[1]).is_err()); // no encapsulation header
    assert!(w.write("/y/has_part", 1, &[0, 1, 0, 0, 1]).is_err()); // unknown topic
    assert!(w.add_topic("/x/has_part", &schema::CLOCK, "q").is_err()); // other type
    w.add_topic("/x/has_part", &schema::BOOL, "q").unwrap(); // same again: fine
    drop(w);
    let f = dir.join("not.mcap");
    std::fs::write(&f, b"hello world").unwrap();
    assert!(BagReader::open(&f).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A killed writer: dropped without finalizing (what SIGKILL leaves: closed chunks on disk,
/// the open chunk and the BufWriter's content lost).
fn killed_bag(dir: &Path, steps: u64) -> Vec<(String, u64, Vec<u8>)> {
    let mut w = BagWriter::create_with(
        dir,
        WriterOptions {
            chunk_bytes: 4096,
            ..Default::default()
        },
    )
    .unwrap();
    let expected = write_fleet(&mut w, steps);
    std::mem::forget(w);
    expected
}

#[test]
fn killed_writer_leaves_flushed_chunks_and_provisional_metadata() {
    let dir = tmp("killed");
    let expected = killed_bag(&dir, 120);
    let r = BagReader::open(&dir).unwrap();
    assert!(!r.complete);
    assert!(BagReader::open_strict(&dir).is_err());
    let n = r.messages.len();
    assert!(n > expected.len() / 2 && n < expected.len(), "{n}");
    assert_same(&r, &expected[..n]);
    // metadata.yaml was rewritten at the last closed chunk: it counts exactly those.
    let m = BagMetadata::read_from(&dir).unwrap();
    assert_eq!(m.message_count, n as u64);

    let out = tmp("killed-recovered");
    let rep = recover(&dir, &out).unwrap();
    assert_eq!(rep.messages, n as u64);
    assert!(!rep.input_was_complete);
    let r2 = BagReader::open_strict(&out).unwrap();
    assert_same(&r2, &expected[..n]);
    assert_eq!(r2.topics, r.topics);
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn recover_after_truncation_at_many_offsets() {
    let dir = tmp("trunc");
    let mut w = BagWriter::create_with(
        &dir,
        WriterOptions {
            chunk_bytes: 3000,
            ..Default::default()
        },
    )
    .unwrap();
    let expected = write_fleet(&mut w, 80);
    w.finish().unwrap();
    let file = dir.join(bag::mcap_file_name(&dir));
    let bytes = std::fs::read(&file).unwrap();
    let s = mcap::Summary::read(&bytes).unwrap().unwrap();
    // messages per chunk, from the message indexes
    let mut chunk_ends: Vec<(u64, usize)> = s
        .chunk_indexes
        .iter()
        .map(|c| {
            let n = s
                .read_message_indexes(&bytes, c)
                .unwrap()
                .values()
                .map(|v| v.len())
                .sum();
            (c.chunk_start_offset + c.chunk_length, n)
        })
        .collect();
    assert_eq!(
        chunk_ends.iter().map(|c| c.1).sum::<usize>(),
        expected.len()
    );
    chunk_ends.sort();
    assert!(chunk_ends.len() >= 5);
    let total = bytes.len();
    let mut cuts: Vec<usize> = (0..40).map(|i| 8 + i * (total - 8) / 40).collect();
    for &(end, _) in &chunk_ends {
        cuts.extend([end as usize - 1, end as usize, end as usize + 1]);
    }
    cuts.push(total - 1);
    let cut_file = tmp("trunc-cut").with_extension("mcap");
    for cut in cuts {
        std::fs::write(&cut_file, &bytes[..cut]).unwrap();
        let want: usize = chunk_ends
            .iter()
            .filter(|(end, _)| *end as usize <= cut)
            .map(|(_, n)| n)
            .sum();
        let out = tmp(&format!("trunc-out-{cut}"));
        let rep = recover(&cut_file, &out).unwrap();
        assert_eq!(rep.messages as usize, want, "cut at {cut} of {total}");
        let r = BagReader::open_strict(&out).unwrap();
        assert_same(&r, &expected[..want]);
        let _ = std::fs::remove_dir_all(&out);
    }
    let _ = std::fs::remove_file(&cut_file);
    // the complete file recovers to everything
    let out = tmp("trunc-full");
    let rep = recover(&file, &out).unwrap();
    assert!(rep.input_was_complete);
    assert_eq!(rep.messages as usize, expected.len());
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn write_contract_adds_topics_with_contract_type_and_qos() {
    let dir = tmp("contract");
    let mut w = BagWriter::create(&dir).unwrap();
    let p = PoseStamped::planar(Time::default(), "map", 1.0, 2.0);
    w.write_contract("/robot_3/pose", 5, &p).unwrap();
    w.write_contract("/robot_3/pose", 6, &p).unwrap();
    w.write_contract("/machine_1/part_ready", 7, &Bool { data: true })
        .unwrap();
    w.write_contract("/clock", 8, &Clock::default()).unwrap();
    assert!(w.write_contract("/robot_3/has_part", 9, &p).is_err()); // wrong type
    assert!(w.write_contract("/not/contract/x", 9, &p).is_err());
    w.finish().unwrap();
    let r = BagReader::open_strict(&dir).unwrap();
    assert_eq!(r.messages.len(), 4);
    let t = &r.topics[r.topic_index("/machine_1/part_ready").unwrap()];
    assert_eq!(t.type_name, "std_msgs/msg/Bool");
    assert_eq!(t.qos_yaml, Profile::PartReady.offered_qos_yaml());
    let t = &r.topics[r.topic_index("/robot_3/pose").unwrap()];
    assert_eq!(t.qos_yaml, Profile::RobotStream.offered_qos_yaml());
    assert_eq!(t.message_count, 2);
    let _ = std::fs::remove_dir_all(&dir);
}
