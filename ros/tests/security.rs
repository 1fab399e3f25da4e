//! DDS Security between Rust participants, in one process on a private domain: a keystore
//! from the `keystore` crate, contexts from `ros::context_with`.
//!
//! - the bridge's enclave publishes a pose that a robot's enclave receives (encrypted);
//! - a participant without security sees none of it, and its `cmd_vel` reaches nobody;
//! - a robot's enclave cannot create a writer on another robot's `cmd_vel`;
//! - a robot's stolen identity with permissions signed by another CA (its own) is
//!   refused by the bridge: its `cmd_vel` reaches nobody;
//! - a tampered permissions document, or an expired or revoked identity, stops the
//!   participant at start (the error names the file);
//! - an identity that expired after its participant started, or whose certificate was
//!   revoked (and the thief deleted its copy of the CRL), is refused by the peers that
//!   meet it: it reads nothing and its `cmd_vel` reaches nobody (the rustdds fix in
//!   docs/upstream/rustdds/0004-*).

mod keystores;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use keystore::{Keystore, Role, Validity};
use msgs::{Bool, PoseStamped, Profile, Twist};
use ros::{context_with, node::node, publisher, subscription, NodeSpec, Security};
use ros2_client::dds::{Context, Node};

fn keystore(name: &str) -> (PathBuf, Keystore) {
    keystores::fleet("sec-it", name)
}

fn enclave(ks: &Keystore, name: &str) -> Security {
    Security::Enclave {
        enclave: name.into(),
        dir: ks.enclave_dir(name),
    }
}

fn participant(domain: u16, sec: &Security, name: &str) -> (Context, Node) {
    let ctx = context_with(domain, sec).unwrap_or_else(|e| panic!("{name}: {e:#}"));
    let spec = NodeSpec {
        namespace: "/",
        name,
        enable_rosout: false,
    };
    let n = node(&ctx, &spec).unwrap();
    (ctx, n)
}

fn pose(x: f64) -> PoseStamped {
    let mut p = PoseStamped::default();
    p.pose.position.x = x;
    p
}

/// Publish with `send` every 50 ms for `secs`, counting what `recv` gets.
fn pump(secs: f64, mut send: impl FnMut(), mut recv: impl FnMut() -> usize) -> usize {
    let t0 = Instant::now();
    let mut got = 0;
    while t0.elapsed().as_secs_f64() < secs {
        send();
        std::thread::sleep(Duration::from_millis(50));
        got += recv();
    }
    got
}

fn drain<M: serde::de::DeserializeOwned + 'static>(s: &ros2_client::Subscription<M>) -> usize {
    let mut n = 0;
    while let Ok(Some(_)) = s.take() {
        n += 1;
    }
    n
}

#[test]
fn enclaves_talk_and_a_participant_without_security_sees_and_moves_nothing() {
    let (root, ks) = keystore("talk");
    let d = test_domains::domain(0);
    let (_bc, mut bridge) = participant(d, &enclave(&ks, keystore::BRIDGE_ENCLAVE), "sim_bridge");
    let (_rc, mut robot) = participant(d, &enclave(&ks, "/tending/robot_0"), "robot_node");
    let (_sc, mut stranger) = participant(d, &Security::Off, "stranger");

    let pose_pub =
        publisher::<PoseStamped>(&mut bridge, "/robot_0/pose", Profile::RobotStream).unwrap();
    let cmd_sub =
        subscription::<Twist>(&mut bridge, "/robot_0/cmd_vel", Profile::RobotStream).unwrap();
    let pose_sub =
        subscription::<PoseStamped>(&mut robot, "/robot_0/pose", Profile::RobotStream).unwrap();
    // A 5-byte sample: its encrypted payload is padded in the DATA submessage (the
    // rustdds fix in docs/upstream/rustdds/0003-*).
    let flag_pub =
        publisher::<Bool>(&mut bridge, "/robot_0/has_part", Profile::RobotStream).unwrap();
    let flag_sub =
        subscription::<Bool>(&mut robot, "/robot_0/has_part", Profile::RobotStream).unwrap();
    let mut flags_got = 0;
    let cmd_pub = publisher::<Twist>(&mut robot, "/robot_0/cmd_vel", Profile::RobotStream).unwrap();
    let spy =
        subscription::<PoseStamped>(&mut stranger, "/robot_0/pose", Profile::RobotStream).unwrap();
    let rogue =
        publisher::<Twist>(&mut stranger, "/robot_0/cmd_vel", Profile::RobotStream).unwrap();
    // Control: the stranger's reader works; it reads an unsecured participant's poses.
    let (_oc, mut open) = participant(d, &Security::Off, "open");
    let open_pub =
        publisher::<PoseStamped>(&mut open, "/robot_9/pose", Profile::RobotStream).unwrap();
    let open_spy =
        subscription::<PoseStamped>(&mut stranger, "/robot_9/pose", Profile::RobotStream).unwrap();
    let mut control = 0;

    // Until the secure pair has matched (authentication, key exchange) and the control
    // reader has seen the open participant: the secure pair can finish first, and then
    // stopping would leave the control at 0 (a fresh-clone run failed that way).
    let t0 = Instant::now();
    let (mut robot_got, mut bridge_got, mut spy_got) = (0, 0, 0);
    while t0.elapsed() < Duration::from_secs(15)
        && (robot_got < 20 || bridge_got < 20 || flags_got < 20 || control == 0)
    {
        let _ = pose_pub.publish(pose(1.0));
        let _ = flag_pub.publish(Bool { data: true });
        let _ = cmd_pub.publish(Twist::planar(0.1, 0.0));
        let _ = rogue.publish(Twist::planar(-9.0, 0.0));
        let _ = open_pub.publish(pose(9.0));
        std::thread::sleep(Duration::from_millis(50));
        robot_got += drain(&pose_sub);
        flags_got += drain(&flag_sub);
        control += drain(&open_spy);
        spy_got += drain(&spy);
        // the bridge counts commands; a rogue one would show as -9
        while let Ok(Some((m, _))) = cmd_sub.take() {
            assert!(
                m.linear.x > 0.0,
                "the stranger's cmd_vel reached the bridge: {m:?}"
            );
            bridge_got += 1;
        }
    }
    assert!(
        robot_got >= 20,
        "robot_0 got {robot_got} poses from the bridge in 15 s"
    );
    assert!(
        bridge_got >= 20,
        "the bridge got {bridge_got} commands from robot_0 in 15 s"
    );
    assert!(
        flags_got >= 20,
        "robot_0 got {flags_got} has_part flags in 15 s"
    );
    assert!(
        control > 0,
        "control: the stranger read no unsecured poses either"
    );
    assert_eq!(spy_got, 0, "a participant without security read poses");
    eprintln!(
        "robot_0 {robot_got} poses, bridge {bridge_got} commands, stranger 0 (control {control})"
    );
    std::fs::remove_dir_all(root).unwrap();
}

#[test]
fn a_robot_enclave_cannot_write_another_robots_cmd_vel() {
    let (root, ks) = keystore("cross");
    let d = test_domains::domain(1);
    let (_rc, mut robot) = participant(d, &enclave(&ks, "/tending/robot_0"), "robot_node");
    assert!(publisher::<Twist>(&mut robot, "/robot_0/cmd_vel", Profile::RobotStream).is_ok());
    let e = publisher::<Twist>(&mut robot, "/robot_1/cmd_vel", Profile::RobotStream)
        .err()
        .expect("robot_0's enclave created a writer on /robot_1/cmd_vel");
    let msg = format!("{e:#}");
    eprintln!("refused: {msg}");
    assert!(msg.contains("security"), "{msg}");
    std::fs::remove_dir_all(root).unwrap();
}

/// robot_0's identity (cert and key) in the hands of someone who signs their own
/// permissions, allowing /robot_1/cmd_vel, with their own CA, and trusts that CA locally:
/// everything verifies on their side, but the bridge checks the permissions against the
/// fleet's CA and refuses them, so their commands reach nobody.
#[test]
fn a_stolen_identity_with_self_signed_permissions_is_refused_by_the_bridge() {
    let (root, ks) = keystore("stolen");
    let (root2, attacker) = keystore("attacker");
    let forged =
        keystores::stolen_identity(&ks, &attacker, "/tending/robot_0", &["robot_0", "robot_1"]);
    let d = test_domains::domain(2);
    let (_bc, mut bridge) = participant(d, &enclave(&ks, keystore::BRIDGE_ENCLAVE), "sim_bridge");
    let (_rc, mut robot1) = participant(d, &enclave(&ks, "/tending/robot_1"), "robot_node");
    let forged_sec = Security::Enclave {
        enclave: "/tending/robot_0".into(),
        dir: forged.clone(),
    };
    let (_ac, mut thief) = participant(d, &forged_sec, "robot_node");

    let cmd_sub =
        subscription::<Twist>(&mut bridge, "/robot_1/cmd_vel", Profile::RobotStream).unwrap();
    let real_pub =
        publisher::<Twist>(&mut robot1, "/robot_1/cmd_vel", Profile::RobotStream).unwrap();
    let rogue = publisher::<Twist>(&mut thief, "/robot_1/cmd_vel", Profile::RobotStream)
        .expect("the thief's own (forged) permissions allow /robot_1/cmd_vel locally");
    let mut real_got = 0;
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(15) && real_got < 20 {
        let _ = real_pub.publish(Twist::planar(0.1, 0.0));
        let _ = rogue.publish(Twist::planar(-9.0, 0.0));
        std::thread::sleep(Duration::from_millis(50));
        while let Ok(Some((m, _))) = cmd_sub.take() {
            assert!(
                m.linear.x > 0.0,
                "the forged robot_0 commanded robot_1: {m:?}"
            );
            real_got += 1;
        }
    }
    assert!(
        real_got >= 20,
        "the bridge got {real_got} of robot_1's own commands"
    );
    // and a second more of rogue commands alone
    let got = pump(
        1.0,
        || {
            let _ = rogue.publish(Twist::planar(-9.0, 0.0));
        },
        || drain(&cmd_sub),
    );
    assert_eq!(got, 0, "the forged robot_0 commanded robot_1");
    std::fs::remove_dir_all(root).unwrap();
    std::fs::remove_dir_all(root2).unwrap();
}

fn refused(dir: &Path, name: &str) -> String {
    let sec = Security::Enclave {
        enclave: name.into(),
        dir: dir.to_path_buf(),
    };
    match context_with(test_domains::domain(3), &sec) {
        Ok(_) => panic!("enclave {} was accepted", dir.display()),
        Err(e) => format!("{e:#}"),
    }
}

#[test]
fn tampered_or_expired_permissions_stop_the_participant_at_start() {
    let (root, ks) = keystore("tamper");
    let dir = ks.enclave_dir("/tending/robot_0");
    let p7s = std::fs::read_to_string(dir.join("permissions.p7s")).unwrap();
    let tampered = p7s.replace("rt/robot_0/cmd_vel", "rt/robot_*/cmd_vel");
    assert_ne!(p7s, tampered);
    std::fs::write(dir.join("permissions.p7s"), tampered).unwrap();
    let msg = refused(&dir, "/tending/robot_0");
    eprintln!("tampered: {msg}");
    assert!(msg.contains("refused enclave `/tending/robot_0`"), "{msg}");

    let past = Validity {
        not_before: time::OffsetDateTime::now_utc() - time::Duration::days(10),
        not_after: time::OffsetDateTime::now_utc() - time::Duration::days(1),
    };
    let old = ks
        .create_enclave(
            "/tending/robot_1",
            &Role::Robots(vec!["robot_1".into()]),
            past,
        )
        .unwrap();
    let msg = refused(&old, "/tending/robot_1");
    eprintln!("expired: {msg}");
    assert!(msg.contains("refused enclave `/tending/robot_1`"), "{msg}");
    // The identity is checked first, and the error names the certificate file.
    assert!(
        msg.contains(&format!("{}", old.join("cert.pem").display())) && msg.contains("expired"),
        "{msg}"
    );
    std::fs::remove_dir_all(root).unwrap();
}

/// The bridge (enclave `/tending/sim_bridge`) and robot_0 meet `suspect` on a fresh
/// domain; robot_0 is the control (it must be matched and exchange data). Returns what
/// the suspect read of robot_1's poses and how many of its commands reached the bridge.
fn bridge_meets(d: u16, ks: &Keystore, suspect: &mut Node) -> (usize, usize) {
    let (_bc, mut bridge) = participant(d, &enclave(ks, keystore::BRIDGE_ENCLAVE), "sim_bridge");
    let (_rc, mut robot0) = participant(d, &enclave(ks, "/tending/robot_0"), "robot_node");
    let pose_pub =
        publisher::<PoseStamped>(&mut bridge, "/robot_1/pose", Profile::RobotStream).unwrap();
    let cmd0 =
        subscription::<Twist>(&mut bridge, "/robot_0/cmd_vel", Profile::RobotStream).unwrap();
    let cmd1 =
        subscription::<Twist>(&mut bridge, "/robot_1/cmd_vel", Profile::RobotStream).unwrap();
    let real_pub =
        publisher::<Twist>(&mut robot0, "/robot_0/cmd_vel", Profile::RobotStream).unwrap();
    let spy = subscription::<PoseStamped>(suspect, "/robot_1/pose", Profile::RobotStream).unwrap();
    let rogue = publisher::<Twist>(suspect, "/robot_1/cmd_vel", Profile::RobotStream)
        .expect("the suspect's own permissions allow /robot_1/cmd_vel locally");
    let (mut control, mut spied, mut commanded) = (0, 0, 0);
    let t0 = Instant::now();
    // Until the control pair has matched, then 2 s more.
    let mut matched_at = None;
    while t0.elapsed() < Duration::from_secs(20)
        && matched_at.is_none_or(|t: Instant| t.elapsed() < Duration::from_secs(2))
    {
        let _ = pose_pub.publish(pose(1.0));
        let _ = real_pub.publish(Twist::planar(0.1, 0.0));
        let _ = rogue.publish(Twist::planar(-9.0, 0.0));
        std::thread::sleep(Duration::from_millis(50));
        control += drain(&cmd0);
        spied += drain(&spy);
        commanded += drain(&cmd1);
        if control >= 20 && matched_at.is_none() {
            matched_at = Some(Instant::now());
        }
    }
    assert!(
        control >= 20,
        "control: the bridge got {control} of robot_0's commands in 20 s"
    );
    eprintln!("control {control} commands; suspect read {spied}, commanded {commanded}");
    (spied, commanded)
}

/// robot_1's identity expires 3 s after its participant started (its permissions stay
/// valid, so only the identity's dates can refuse it). Its own start-up check passed;
/// the bridge, meeting it after the expiry, must refuse it.
#[test]
fn an_identity_that_expired_after_start_is_refused_by_peers_that_meet_it_later() {
    let (root, ks) = keystore("expiring");
    let dir = ks.enclave_dir("/tending/robot_1");
    let permissions = std::fs::read(dir.join("permissions.p7s")).unwrap();
    let now = time::OffsetDateTime::now_utc();
    let soon = Validity {
        not_before: now - time::Duration::hours(1),
        not_after: now + time::Duration::seconds(3),
    };
    ks.create_enclave(
        "/tending/robot_1",
        &Role::Robots(vec!["robot_1".into()]),
        soon,
    )
    .unwrap();
    std::fs::write(dir.join("permissions.p7s"), permissions).unwrap();
    let d = test_domains::domain(4);
    let (_sc, mut suspect) = participant(d, &enclave(&ks, "/tending/robot_1"), "robot_node");
    // past notAfter (whole seconds in the certificate) with a margin
    std::thread::sleep(Duration::from_secs(5));
    let (spied, commanded) = bridge_meets(d, &ks, &mut suspect);
    assert_eq!(spied, 0, "an expired identity read robot_1's poses");
    assert_eq!(commanded, 0, "an expired identity commanded robot_1");
    std::fs::remove_dir_all(root).unwrap();
}

/// `tending security revoke /tending/robot_1` puts robot_1's certificate on the CRL
/// every enclave holds: robot_1 refuses to start with it, naming both files; with its
/// copy of the CRL deleted (a thief would) it starts, and the bridge refuses it.
#[test]
fn a_revoked_identity_is_refused_at_start_and_by_its_peers() {
    let (root, ks) = keystore("revoked");
    ks.revoke("/tending/robot_1").unwrap();
    let dir = ks.enclave_dir("/tending/robot_1");
    let msg = refused(&dir, "/tending/robot_1");
    eprintln!("revoked: {msg}");
    for needle in ["revoked", "cert.pem", "crl.pem"] {
        assert!(msg.contains(needle), "no `{needle}` in: {msg}");
    }

    std::fs::remove_file(dir.join("crl.pem")).unwrap();
    let d = test_domains::domain(5);
    let (_sc, mut thief) = participant(d, &enclave(&ks, "/tending/robot_1"), "robot_node");
    let (spied, commanded) = bridge_meets(d, &ks, &mut thief);
    assert_eq!(spied, 0, "a revoked identity read robot_1's poses");
    assert_eq!(commanded, 0, "a revoked identity commanded robot_1");
    std::fs::remove_dir_all(root).unwrap();
}

/// Keystores cover domains 0..=230 (Cyclone DDS refuses to parse a governance or
/// permissions document naming a higher one); a secure participant on 231 or 232, which
/// ROS allows, is refused at start with the reason instead of failing inside DDS.
#[test]
fn a_secure_participant_above_domain_230_is_refused_with_the_reason() {
    let (root, ks) = keystore("domain");
    let sec = enclave(&ks, "/tending/robot_0");
    for d in [231, 232] {
        let msg = match context_with(d, &sec) {
            Ok(_) => panic!("a secure participant started on domain {d}"),
            Err(e) => format!("{e:#}"),
        };
        assert!(msg.contains(&format!("domain {d} is above 230")), "{msg}");
    }
    std::fs::remove_dir_all(root).unwrap();
}
