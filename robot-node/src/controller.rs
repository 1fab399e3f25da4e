//! Controllers: observation in, planar velocity (m/s, map frame) out. One concept for the
//! whole project (issue 45): the trait and the scripted controllers live in
//! `plan::controller`, the learned policy in `policy::controller`; robot_node runs them
//! per robot. The tests below drive them as robot_node does.

pub use plan::controller::{
    Controller, GreedyController, GreedyOrcaController, MatchingOrcaController,
};
pub use policy::controller::{checkpoint_k_speed, PolicyController};

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use obs::{ObsBatch, ObsBuilder};
    use plan::greedy::GreedyParams;
    use plan::orca::OrcaParams;
    use plan::{FilterMargins, FleetParams, Outputs, Safety};

    /// Greedy parameters of the default scenario (also used by the tick and fan-out tests).
    pub(crate) fn params(k: f32) -> GreedyParams {
        GreedyParams {
            k_speed: k,
            ..GreedyParams::default()
        }
    }

    /// The default fleet (robot_node's default parameters: `node` tests they agree).
    pub(crate) fn fleet() -> FleetParams {
        let g = params(0.5);
        FleetParams::from_greedy(&g, 2.3)
    }

    fn b(own: [f32; 2], has_part: bool, m: Vec<([f32; 2], bool)>, s: Vec<[f32; 2]>) -> ObsBatch {
        ObsBuilder {
            own_pos: own,
            has_part,
            machines: m,
            storages: s,
            peers: vec![],
        }
        .build()
        .unwrap()
    }

    // `obs::action::MOVES` indices the greedy tests expect
    const STAY: u8 = 0;
    const DOWN: u8 = 3;
    const UP: u8 = 4;

    #[test]
    fn goes_to_nearest_ready_machine() {
        let g = GreedyController::new(params(0.5));
        let o = b(
            [0.0, 0.0],
            false,
            vec![([0.5, 0.2], false), ([0.0, -0.6], true), ([0.9, 0.9], true)],
            vec![[-1.0, 0.0]],
        );
        assert_eq!(g.action(&o).unwrap(), DOWN);
        let mut g2 = g.clone();
        assert_eq!(g2.act(&o).unwrap(), [0.0, -0.5]);
    }

    #[test]
    fn stays_when_no_machine_is_ready() {
        let g = GreedyController::new(params(0.5));
        let o = b(
            [0.0, 0.0],
            false,
            vec![([-0.4, 0.1], false), ([0.9, 0.9], false)],
            vec![[1.0, -1.0]],
        );
        assert_eq!(g.action(&o).unwrap(), STAY);
    }

    #[test]
    fn with_part_goes_to_storage() {
        let g = GreedyController::new(params(0.3));
        let o = b(
            [0.0, 0.0],
            true,
            vec![([0.6, -0.6], true)],
            vec![[0.2, 0.7], [1.0, 1.0]],
        );
        assert_eq!(g.action(&o).unwrap(), UP);
        let o = b([0.0, 0.0], true, vec![([0.6, 0.0], true)], vec![]);
        assert_eq!(g.action(&o).unwrap(), STAY);
    }

    #[test]
    fn refuses_invalid_batches() {
        let g = GreedyController::new(params(0.5));
        let mut o = b([0.0, 0.0], false, vec![([0.5, 0.0], true)], vec![]);
        o.machines[0] = f32::NAN;
        assert!(g.action(&o).is_err());
        let o2 = ObsBatch::zeros(2, Default::default());
        assert!(g.action(&o2).is_err());
    }

    fn tmp(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("robot_node_{}_{name}", std::process::id()))
    }

    fn small_arch() -> policy::ArchConfig {
        let mut arch = policy::ArchConfig::smappo();
        arch.d_model = 8;
        arch.heads = 2;
        arch.hidden = 8;
        arch
    }

    #[test]
    fn policy_controller_loads_checkpoint_keeps_and_resets_state() {
        let actor = policy::Actor::new(small_arch(), 7);
        let path = tmp("ok.safetensors");
        policy::checkpoint::save_policy(
            &path,
            &actor,
            serde_json::json!({"setup": "6.4_2", "k_speed": 0.3}),
        )
        .unwrap();
        let (c, from_meta) = PolicyController::load(&path, 0.5).unwrap();
        assert!(from_meta);
        assert_eq!(c.k_speed, 0.3);
        let mut c = c.with_pilot(fleet(), Safety::RAW).unwrap();
        let o = b(
            [0.1, -0.2],
            false,
            vec![([0.5, 0.5], true), ([-0.5, 0.5], false)],
            vec![[0.0, -0.9]],
        );
        // same decisions as the policy crate's own inference from a zero state
        let mut reference = policy::Policy::load(&path).unwrap();
        let mut st = reference.new_state();
        for _ in 0..3 {
            let a = reference.act(&o, &mut st, policy::ActMode::Greedy).unwrap();
            let v = c.act(&o).unwrap();
            assert_eq!(Some(v), obs::action::velocity(a, 0.3));
        }
        assert!(c.state().h.iter().any(|v| *v != 0.0));
        assert_eq!(c.state().h, st.h);
        c.reset();
        assert!(c.state().h.iter().all(|v| *v == 0.0));
        std::fs::remove_file(&path).ok();
    }

    #[test]
    fn policy_controller_refuses_bad_files_with_clear_errors() {
        let missing = tmp("missing.safetensors");
        let e = PolicyController::load(&missing, 0.5).err().unwrap();
        assert!(format!("{e:#}").contains("cannot load policy"), "{e:#}");
        let junk = tmp("junk.safetensors");
        std::fs::write(&junk, b"this is not a checkpoint").unwrap();
        let e = PolicyController::load(&junk, 0.5).err().unwrap();
        let msg = format!("{e:#}");
        assert!(
            msg.contains("junk.safetensors") && msg.contains("corrupt"),
            "{msg}"
        );
        std::fs::remove_file(&junk).ok();
    }

    #[test]
    fn greedy_orca_heads_for_the_machine_and_refuses_bad_batches() {
        let p = OrcaParams::new(params(0.5), 2.3, 0.08);
        let mut c = GreedyOrcaController::new(p).unwrap();
        let o = b(
            [0.0, 0.0],
            false,
            vec![([0.8, 0.0], true)],
            vec![[-0.8, 0.8]],
        );
        let v = c.act(&o).unwrap();
        assert!(v[0] > 0.4 && v[1].abs() < 0.05, "{v:?}");
        c.reset();
        assert!(c.act(&ObsBatch::zeros(2, Default::default())).is_err());
        let mut bad = p;
        bad.greedy.dt = f32::NAN;
        assert!(GreedyOrcaController::new(bad).is_err());
    }

    #[test]
    fn shielded_policy_only_takes_safe_actions() {
        let shield = Safety {
            shield: true,
            filter: None,
        };
        // Peers touching-close on all four sides: only "stay" is safe.
        let peers = [[0.17, 0.0], [-0.17, 0.0], [0.0, 0.17], [0.0, -0.17]];
        let o = ObsBuilder {
            own_pos: [0.0, 0.0],
            has_part: false,
            machines: vec![([0.8, 0.8], true)],
            storages: vec![[-0.8, 0.8]],
            peers: peers.iter().map(|p| (*p, false)).collect(),
        }
        .build()
        .unwrap();
        let mut unshielded_moves = 0;
        for seed in 0..8 {
            let actor = policy::Actor::new(small_arch(), seed);
            let pol = policy::Policy::from_actor(actor, serde_json::Value::Null);
            let mut free = PolicyController::from_policy(pol.clone(), 0.5)
                .with_pilot(fleet(), Safety::RAW)
                .unwrap();
            unshielded_moves += (free.action(&o).unwrap() != STAY) as usize;
            let mut c = PolicyController::from_policy(pol, 0.5)
                .with_pilot(fleet(), shield)
                .unwrap();
            assert_eq!(c.action(&o).unwrap(), STAY, "seed {seed}");
        }
        // The check means something only if unshielded actors would have moved.
        assert!(unshielded_moves > 0);
    }

    #[test]
    fn orca_filter_keeps_free_moves_and_holds_back_near_peers() {
        let free = b(
            [0.0, 0.0],
            false,
            vec![([0.9, 0.9], true)],
            vec![[-0.9, 0.9]],
        );
        let peers = [[0.17, 0.0], [-0.17, 0.0], [0.0, 0.17], [0.0, -0.17]];
        let boxed = ObsBuilder {
            own_pos: [0.0, 0.0],
            has_part: false,
            machines: vec![([0.9, 0.9], true)],
            storages: vec![[-0.9, 0.9]],
            peers: peers.iter().map(|p| (*p, false)).collect(),
        }
        .build()
        .unwrap();
        // greedy-ORCA's own clearance, fixed
        let margins = FilterMargins {
            clearance: plan::orca::GREEDY_ORCA_CLEARANCE,
            rest_clearance: plan::orca::GREEDY_ORCA_CLEARANCE,
            obstacle_horizon: plan::orca::OBSTACLE_HORIZON,
        };
        for seed in 0..4 {
            let pol = policy::Policy::from_actor(
                policy::Actor::new(small_arch(), seed),
                Default::default(),
            );
            let mut plain = PolicyController::from_policy(pol.clone(), 0.5)
                .with_pilot(fleet(), Safety::RAW)
                .unwrap();
            let mut c = PolicyController::from_policy(pol, 0.5)
                .with_pilot(fleet(), Safety::filtered(margins))
                .unwrap();
            assert!(c.filtered() && !plain.filtered());
            // Nothing near: ORCA leaves the policy's move as it is.
            let (v, w) = (plain.act(&free).unwrap(), c.act(&free).unwrap());
            assert!(
                (v[0] - w[0]).abs() < 1e-4 && (v[1] - w[1]).abs() < 1e-4,
                "{v:?} {w:?}"
            );
            // Peers 1 cm away on every side: no move at speed toward any of them.
            c.reset();
            let w = c.act(&boxed).unwrap();
            assert!(w[0].abs() < 0.25 && w[1].abs() < 0.25, "{w:?}");
        }
    }

    /// A target-action policy drives straight for the box it picks (here always the
    /// greedy entry: toward the ready machine at full speed); it refuses to act without its
    /// pilot and the shield; matching-ORCA heads for the same machine, alone.
    #[test]
    fn target_policy_drives_to_the_chosen_box() {
        let mut arch = small_arch();
        arch.n_actions = plan::targets::N_TARGET_ACTIONS;
        arch.actions = policy::ActionSpace::Targets;
        let mut actor = policy::Actor::new(arch, 1);
        actor.add_action_bias(plan::targets::TargetAction::Greedy as usize, 1e4);
        let pol = policy::Policy::from_actor(actor, Default::default());
        let obs = b(
            [0.0, 0.0],
            false,
            vec![([0.9, 0.0], true)],
            vec![[-0.9, 0.9]],
        );
        let mut bare = PolicyController::from_policy(pol.clone(), 0.5);
        assert_eq!(bare.outputs(), Outputs::Targets);
        assert!(bare.act(&obs).unwrap_err().to_string().contains("pilot"));
        let shield = Safety {
            shield: true,
            filter: None,
        };
        let e = PolicyController::from_policy(pol.clone(), 0.5)
            .with_pilot(fleet(), shield)
            .err()
            .unwrap();
        assert!(e.to_string().contains("target actions"), "{e}");
        let mut c = PolicyController::from_policy(pol, 0.5)
            .with_pilot(fleet(), Safety::filtered(FilterMargins::DEPLOYED))
            .unwrap();
        let v = c.act(&obs).unwrap();
        assert!((v[0] - 0.5).abs() < 1e-3 && v[1].abs() < 1e-3, "{v:?}");
        let mut m = MatchingOrcaController::new(&fleet(), FilterMargins::DEPLOYED).unwrap();
        let w = m.act(&obs).unwrap();
        assert!((w[0] - 0.5).abs() < 1e-3 && w[1].abs() < 1e-3, "{w:?}");
        assert!(m.act(&ObsBatch::zeros(2, Default::default())).is_err());
    }

    #[test]
    fn k_speed_metadata_forms() {
        use serde_json::json;
        assert_eq!(checkpoint_k_speed(&json!({"k_speed": 0.4})), Some(0.4));
        assert_eq!(
            checkpoint_k_speed(&json!({"scenario": {"task": {"k_speed": 0.2}}})),
            Some(0.2)
        );
        assert_eq!(checkpoint_k_speed(&json!({"k_speed": -1.0})), None);
        assert_eq!(checkpoint_k_speed(&serde_json::Value::Null), None);
    }
}
