//! Randomized setups (SetupRange, Trainer::new_randomized).

use super::*;

fn small_randomized(kind: ModelKind, range: &str, seed: u64) -> Trainer {
    let (cfg, sc) = (tiny(TrainConfig::default()), short_episodes());
    Trainer::new_randomized(kind, cfg, sc, range.parse().unwrap(), 8, seed).unwrap()
}

#[test]
fn setup_range_parsing() {
    let r: SetupRange = "2..12.2..8_1..4".parse().unwrap();
    assert_eq!(r.lo, Setup::new(2, 2, 1));
    assert_eq!(r.hi, Setup::new(12, 8, 4));
    assert_eq!(r.to_string(), "2..12.2..8_1..4");
    assert_eq!(r.len(), 11 * 7 * 4);
    // dashes, `_` for `.`, spaces, fixed counts, a plain setup name
    for s in ["2-12.2-8_1-4", "2..12_2..8_1..4", " 2..12.2..8_1..4 "] {
        assert_eq!(s.parse::<SetupRange>().unwrap(), r, "{s}");
    }
    let f: SetupRange = "6.2..8_2".parse().unwrap();
    assert_eq!((f.lo, f.hi), (Setup::new(6, 2, 2), Setup::new(6, 8, 2)));
    assert_eq!(f.to_string(), "6.2..8_2");
    let one: SetupRange = "6.4_2".parse().unwrap();
    assert_eq!(
        (one.lo, one.hi, one.len()),
        (Setup::new(6, 4, 2), Setup::new(6, 4, 2), 1)
    );
    assert_eq!(
        "4..4.2_2".parse::<SetupRange>().unwrap().to_string(),
        "4.2_2"
    );
    // bad strings: a clear error naming the input and the problem
    for (s, why) in [
        ("", "empty"),
        ("2..12.2..8", "2 count fields"),
        ("2..12.2..8_1..4_3", "4 count fields"),
        ("12..2.2_2", "robots range 12..2 is empty"),
        ("2..4.8..3_2", "machines range 8..3 is empty"),
        ("0..4.2_2", "robots must be >= 1"),
        ("2..4.2_0..1", "storages must be >= 1"),
        ("a..4.2_2", "robots `a..4` is not a count"),
        ("2..4.x_2", "machines `x` is not a count"),
        ("2...4.2_2", "count fields"),
        ("2..4..6.2_2", "robots `2..4..6`"),
        ("-1..4.2_2", "robots `..1..4`"),
        ("2..4.2_1..", "storages `1..`"),
    ] {
        let e = s.parse::<SetupRange>().unwrap_err().to_string();
        assert!(e.contains(&format!("`{s}`")), "{s}: {e}");
        assert!(e.contains(why), "{s}: {e}");
    }
}

/// The draw of update u is a pure function of (seed, u): same seed, same sequence (also
/// from a second trainer), another seed another sequence; every draw lies in the range
/// and every count of each range is drawn.
#[test]
fn randomized_draws_are_deterministic_and_in_range() {
    let range = "2..4.1..3_1..2";
    let a = small_randomized(ModelKind::Smappo, range, 7);
    let b = small_randomized(ModelKind::Smappo, range, 7);
    let c = small_randomized(ModelKind::Smappo, range, 8);
    let r: SetupRange = range.parse().unwrap();
    let seq = |t: &Trainer| (0..300).map(|u| t.setup_for_update(u)).collect::<Vec<_>>();
    let (sa, sb, sc) = (seq(&a), seq(&b), seq(&c));
    assert_eq!(sa, sb);
    assert_ne!(sa, sc);
    assert!(sa.iter().chain(&sc).all(|&s| r.contains(s)));
    let mut seen = std::collections::HashSet::new();
    seen.extend(sa.iter().copied());
    assert_eq!(
        seen.len(),
        r.len(),
        "all {} setups of {range} drawn",
        r.len()
    );
    assert_eq!(a.current_setup(), sa[0]);
    assert_eq!(a.schedule_string(), "2..4.1..3_1..2:8");
}

/// Ranges the layout generator or the MAPPO padding cannot take are refused up front
/// with the range and the reason in the message; a 0-episode budget too.
#[test]
fn randomized_refuses_bad_ranges() {
    let sc = ScenarioConfig::default();
    let cfg = TrainConfig::default();
    let try_new = |kind, r: &str, eps| {
        Trainer::new_randomized(kind, cfg.clone(), sc.clone(), r.parse().unwrap(), eps, 0)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    };
    let e = try_new(ModelKind::Mappo, "2..43.2_2", 8);
    assert!(
        e.contains("2..43.2_2") && e.contains("mappo_max_robots = 42"),
        "{e}"
    );
    let e = try_new(ModelKind::Mappo, "2.2..30_2", 8);
    assert!(e.contains("mappo_max_machines = 28"), "{e}");
    let e = try_new(ModelKind::Mappo, "2.2_1..15", 8);
    assert!(e.contains("mappo_max_storages = 14"), "{e}");
    // SMAPPO has no padding, but the room has a limit
    let e = try_new(ModelKind::Smappo, "2..100000.2_2", 8);
    assert!(
        e.contains("100000.2_2") && e.contains("does not fit"),
        "{e}"
    );
    let e = try_new(ModelKind::Smappo, "2.2_2", 0);
    assert!(e.contains("0 episodes"), "{e}");
    // the paper's whole zero-shot span is accepted, for both models
    for kind in [ModelKind::Smappo, ModelKind::Mappo] {
        assert_eq!(try_new(kind, "2..42.2..28_1..14", 8), "");
    }
    // MAPPO: actor padded to the config's maxima, critic to the range's most robots
    let t = small_randomized(ModelKind::Mappo, "2..5.1..3_1..2", 0);
    let fixed = {
        let sc = short_episodes();
        Trainer::new(
            ModelKind::Mappo,
            t.cfg.clone(),
            sc,
            parse_curriculum("5.3_2:8").unwrap(),
            0,
        )
        .unwrap()
    };
    assert_eq!(t.actor.arch, fixed.actor.arch);
    assert_eq!(t.critic.arch, fixed.critic.arch);
}

/// Randomized training: each update trains on its draw (logged in `setup`), and
/// 2 updates + save + resume + 1 update == 3 updates straight, bit for bit, both models.
#[test]
fn randomized_resume_is_bit_exact() {
    let range = "2..3.1..2_1..2";
    let r: SetupRange = range.parse().unwrap();
    for kind in [ModelKind::Smappo, ModelKind::Mappo] {
        let mut a = small_randomized(kind, range, 3);
        let mut stats_a = vec![];
        for u in 0..3 {
            let want = a.setup_for_update(u);
            let s = a.step().unwrap();
            assert_eq!(s.setup, want.to_string());
            assert!(r.contains(s.setup.parse().unwrap()));
            stats_a.push(s);
        }
        let drawn: std::collections::HashSet<_> = stats_a.iter().map(|s| &s.setup).collect();
        assert!(
            drawn.len() > 1,
            "seed 3 draws more than one setup: {drawn:?}"
        );
        let robots: u64 = stats_a
            .iter()
            .map(|s| s.setup.parse::<Setup>().unwrap().robots as u64)
            .sum();
        assert_eq!(a.agent_steps, 2 * 40 * robots);

        let mut b = small_randomized(kind, range, 3);
        b.step().unwrap();
        b.step().unwrap();
        let p = tmp(&format!("resume-rand-{kind}.safetensors"));
        b.save_state(&p).unwrap();
        drop(b);
        let mut c = Trainer::resume(&p, None).unwrap();
        assert_eq!(c.randomize, Some(r));
        assert_eq!(c.schedule_string(), format!("{range}:8"));
        assert_eq!(c.update, 2);
        let s3 = c.step().unwrap();
        assert_eq!(s3.setup, stats_a[2].setup);
        assert_same_learner(&c, &a, kind);
        assert_eq!(s3.team_reward, stats_a[2].team_reward);
        assert_eq!(s3.value_loss, stats_a[2].value_loss);
        assert_eq!(c.agent_steps, a.agent_steps);
        // budget of 8 episodes = 4 updates of 2 envs
        c.step().unwrap();
        assert!(c.finished());
        assert!(c.step().is_err());
        // extend: still randomized, same range
        c.set_total_episodes(10).unwrap();
        assert!(!c.finished() && c.randomize == Some(r));
        assert_eq!(c.total_episodes(), 10);
        // the policy checkpoint names the range
        let meta = c.training_meta();
        assert_eq!(meta["setup"], range);
        assert_eq!(meta["randomize"], range);
    }
}

/// Switching schedules on a (resumed) run: a randomized run can move to fixed setups and
/// back; a range that would change MAPPO's critic is refused.
#[test]
fn randomized_schedule_switches() {
    let mut t = small_randomized(ModelKind::Mappo, "2..3.1..2_1..2", 1);
    t.step().unwrap();
    // same most-robots (3): accepted
    t.set_schedule(parse_curriculum("3.2_2:6").unwrap())
        .unwrap();
    assert_eq!(t.randomize, None);
    assert_eq!(t.current_setup(), Setup::new(3, 2, 2));
    assert_eq!(t.schedule_string(), "3.2_2:6");
    t.set_randomize("1..3.2_2".parse().unwrap(), 20).unwrap();
    assert_eq!(t.schedule_string(), "1..3.2_2:20");
    assert!(t.stage == 0 && t.stage_episodes == 2);
    let e = t
        .set_randomize("2..4.2_2".parse().unwrap(), 20)
        .unwrap_err()
        .to_string();
    assert!(e.contains("network shapes"), "{e}");
    assert!(t.set_total_episodes(0).is_err());
    t.set_total_episodes(2).unwrap();
    assert!(t.finished(), "2 episodes already trained");
}
