//! Secure interop with Eclipse Cyclone DDS 0.10 (Debian's packages, with the DDS Security
//! plugins; issue 38): a C peer (`tests/cyclone/cyclone_peer.c`, built by
//! `tests/cyclone/build.sh`, which installs the packages if they are missing) configured
//! the way rmw_cyclonedds configures an SROS2 enclave (participant properties naming the
//! enclave's six files), against our participants (`ros::context_with`, what every fleet
//! process uses) with enclaves that `keystore` (`tending security create`) made.
//!
//! - with robot_0's enclave, Cyclone creates its participant (it used to refuse our
//!   governance: "Can not parse governance file (code: 137)"), authenticates with the
//!   bridge's enclave (our log says so), reads the poses the bridge publishes on
//!   `rt/robot_0/pose` (every other one with a 3000-character frame_id, which RustDDS
//!   sends in encrypted fragments), and its `rt/robot_0/cmd_vel` reaches the bridge;
//! - a Cyclone participant without security reads nothing and commands nobody, while it
//!   reads an unsecured participant's topic on the same domain (the control);
//! - a Cyclone participant with robot_0's enclave from another keystore (another CA) is
//!   refused both ways: it reads nothing and its commands reach nobody; Cyclone refuses
//!   our bridge's certificate (its log says why) and our recorder refuses Cyclone's (our
//!   log says why). Which side of a pair checks the other's certificate first is fixed
//!   by their GUIDs, which come from the certificate subjects: the lower one sends the
//!   handshake request, the other checks it (sim_bridge a24ac186.. < robot_0
//!   b18719de.. < recorder f2770dff..).
//!
//! Debugging: `RUST_LOG=...` prints RustDDS's log instead of capturing it;
//! `CYCLONE_PEER_URI` replaces the peer's Cyclone configuration (e.g. a finest trace).

mod cyclone_peer;
mod keystores;

use cyclone_peer::*;
use msgs::{PoseStamped, Profile, Twist};
use ros::{publisher, subscription, Security};

/// Cyclone with `robot`'s enclave reads the bridge's poses of `robot` and commands it.
fn cyclone_robot_talks_to_the_bridge(name: &str, d: u16, robot: &str) {
    let (root, ks) = keystore(name);
    let (_bc, mut bridge) = participant(d, &enclave(&ks, keystore::BRIDGE_ENCLAVE), "sim_bridge");
    let dir = ks.enclave_dir(&keystore::robot_enclave(robot));
    let peer = spawn_peer(PeerRun {
        domain: d,
        robot,
        enclave: Some(&dir),
        vx: 0.25,
        secs: 40.0,
        until: Some(20),
        read2: None,
    });
    let (r, b) = bridge_with_peer(&mut bridge, robot, peer, || ());
    assert!(
        r.refused.is_none(),
        "Cyclone refused our enclave:\n{}",
        r.log
    );
    assert!(r.read >= 20, "Cyclone read {} poses:\n{}", r.read, r.log);
    assert!(
        r.big >= 5,
        "Cyclone read {} fragmented poses:\n{}",
        r.big,
        r.log
    );
    assert_eq!(r.last_x, 1.5, "Cyclone read a wrong pose");
    assert!(
        b.cmds.len() >= 10,
        "the bridge got {} of Cyclone's commands:\n{}",
        b.cmds.len(),
        r.log
    );
    assert!(b.cmds.iter().all(|&x| x == 0.25), "{:?}", b.cmds);
    // The bridge authenticated it as an ordinary peer.
    let ok = our_log(&r.guid, "Authenticated successfully");
    assert!(!ok.is_empty(), "no authentication of {} in our log", r.guid);
    std::fs::remove_dir_all(root).unwrap();
}

/// robot_0's GUID (from its certificate's subject) is above the bridge's, so the bridge
/// sends the handshake request and Cyclone replies.
#[test]
fn a_cyclone_peer_with_a_robot_enclave_reads_the_pose_and_commands_the_robot() {
    cyclone_robot_talks_to_the_bridge("peer", test_domains::domain(0), "robot_0");
}

/// robot_1's GUID is below the bridge's: Cyclone sends the request and the bridge
/// replies with its certificate and permissions, a ~4.7 kB sample sent in fragments
/// whose size ends on the ECDSA signature's 70-72 bytes. Before rustdds patch 0019 the
/// final fragment was not padded to 4 bytes, Cyclone refused it as malformed in most
/// runs, and the two never authenticated.
#[test]
fn a_cyclone_peer_that_sends_the_handshake_request_authenticates_too() {
    cyclone_robot_talks_to_the_bridge("request", test_domains::domain(3), "robot_1");
}

/// A Cyclone participant without security, beside the secure bridge and robot_0, and
/// beside an unsecured Rust participant publishing `/robot_9/pose` (the control: it
/// reads that one, so it is on the domain and discovery works).
#[test]
fn an_unauthenticated_cyclone_participant_reads_nothing_and_commands_nobody() {
    let (root, ks) = keystore("open");
    let d = test_domains::domain(1);
    let (_bc, mut bridge) = participant(d, &enclave(&ks, keystore::BRIDGE_ENCLAVE), "sim_bridge");
    let (_rc, mut robot) = participant(d, &enclave(&ks, "/tending/robot_0"), "robot_node");
    let (_oc, mut open) = participant(d, &Security::Off, "open");
    let robot_pose =
        subscription::<PoseStamped>(&mut robot, "/robot_0/pose", Profile::RobotStream).unwrap();
    let robot_cmd =
        publisher::<Twist>(&mut robot, "/robot_0/cmd_vel", Profile::RobotStream).unwrap();
    let open_pub =
        publisher::<PoseStamped>(&mut open, "/robot_9/pose", Profile::RobotStream).unwrap();
    let mut robot_got = 0;
    let peer = spawn_peer(PeerRun {
        domain: d,
        robot: "robot_0",
        enclave: None,
        vx: -9.0,
        secs: 10.0,
        until: None,
        read2: Some("rt/robot_9/pose"),
    });
    let (r, b) = bridge_with_peer(&mut bridge, "robot_0", peer, || {
        let _ = open_pub.publish(pose(9.0));
        let _ = robot_cmd.publish(Twist::planar(0.1, 0.0));
        while let Ok(Some(_)) = robot_pose.take() {
            robot_got += 1;
        }
    });
    assert!(r.refused.is_none(), "{}", r.log);
    assert!(
        r.read2 > 0,
        "control: Cyclone read no unsecured poses either:\n{}",
        r.log
    );
    assert!(robot_got > 0, "control: robot_0 (secure) read no poses");
    assert!(
        b.cmds.contains(&0.1),
        "control: no command of robot_0 reached the bridge"
    );
    assert_eq!(
        r.read, 0,
        "an unauthenticated Cyclone participant read poses"
    );
    assert_eq!(r.matched_sub + r.matched_pub, 0, "it was matched: {r:?}");
    assert!(
        !b.cmds.contains(&-9.0),
        "an unauthenticated Cyclone participant commanded robot_0"
    );
    std::fs::remove_dir_all(root).unwrap();
}

/// robot_0's enclave from another keystore (another CA, everything signed by it): a
/// valid identity that our fleet does not trust, and that does not trust ours.
#[test]
fn a_cyclone_peer_with_another_cas_certificate_is_refused_both_ways() {
    let (root, ks) = keystore("ca");
    let (root2, other) = keystore("other-ca");
    let d = test_domains::domain(2);
    let (_bc, mut bridge) = participant(d, &enclave(&ks, keystore::BRIDGE_ENCLAVE), "sim_bridge");
    // Control: our robot_0 meanwhile reads the bridge's poses and commands robot_0.
    let (_rc, mut robot) = participant(d, &enclave(&ks, "/tending/robot_0"), "robot_node");
    // Our recorder, whose GUID is above Cyclone's, checks Cyclone's certificate (and
    // reads the poses too, a second control).
    let (_cc, mut recorder) = participant(d, &enclave(&ks, keystore::RECORDER_ENCLAVE), "recorder");
    let recorder_pose =
        subscription::<PoseStamped>(&mut recorder, "/robot_0/pose", Profile::RobotStream).unwrap();
    let mut recorder_got = 0;
    let robot_pose =
        subscription::<PoseStamped>(&mut robot, "/robot_0/pose", Profile::RobotStream).unwrap();
    let robot_cmd =
        publisher::<Twist>(&mut robot, "/robot_0/cmd_vel", Profile::RobotStream).unwrap();
    let mut robot_got = 0;
    let dir = other.enclave_dir("/tending/robot_0");
    let peer = spawn_peer(PeerRun {
        domain: d,
        robot: "robot_0",
        enclave: Some(&dir),
        vx: -9.0,
        secs: 10.0,
        until: None,
        read2: None,
    });
    let (r, b) = bridge_with_peer(&mut bridge, "robot_0", peer, || {
        let _ = robot_cmd.publish(Twist::planar(0.1, 0.0));
        while let Ok(Some(_)) = robot_pose.take() {
            robot_got += 1;
        }
        while let Ok(Some(_)) = recorder_pose.take() {
            recorder_got += 1;
        }
    });
    assert!(r.refused.is_none(), "its own enclave is valid:\n{}", r.log);
    assert!(robot_got > 0, "control: robot_0 read no poses");
    assert!(recorder_got > 0, "control: the recorder read no poses");
    // Our side: the recorder refused its certificate.
    let ours = kept_out(
        &r,
        &b,
        "a Cyclone peer of another CA",
        "Replying to a handshake request failed",
    );
    eprintln!(
        "our side refused it {} times, e.g.: {}",
        ours.len(),
        ours[0]
    );
    // Cyclone's side: it refused our bridge's certificate.
    let theirs: Vec<&str> = r
        .cyclone_log
        .lines()
        // e.g. "Begin handshake reply failed: Certificate not valid: error: unable to get
        // local issuer certificate; subject: /CN=\/tending\/sim_bridge(code: 200)"
        .filter(|l| l.contains("handshake") && l.contains("failed") && l.contains("sim_bridge"))
        .collect();
    assert!(
        !theirs.is_empty(),
        "no refusal in Cyclone's log:\n{}",
        r.cyclone_log
    );
    eprintln!(
        "Cyclone refused {} times, e.g.: {}",
        theirs.len(),
        theirs[0]
    );
    std::fs::remove_dir_all(root).unwrap();
    std::fs::remove_dir_all(root2).unwrap();
}
