//! A target-action "policy" that always asks for one menu entry (`plan::targets`), written
//! as a checkpoint so `tending eval`, `tending fleet` and robot_node run it like any other:
//! entry 1 is greedy-ORCA with the policy's planner, entry 7 ("matched") the matching-ORCA
//! script of docs/RESULTS.md 7.8. The scripts a learned menu policy must beat are these.
//! matching-ORCA itself is a scripted method (`plan::MatchingOrca`: `tending eval
//! --policy matching-orca`, robot_node `-p controller:=matching-orca`), step for step the
//! checkpoint this writes for entry 7 (tested in policy/src/train/tests.rs); this example
//! stays for the other entries, as ablations.
//!
//! cargo run --release -p policy --example always_entry -- ENTRY OUT.safetensors

use plan::targets::{TargetAction, N_TARGET_ACTIONS};
use policy::{checkpoint::save_policy, ActionSpace, Actor, ArchConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(entry), Some(out)) = (args.first(), args.get(1)) else {
        return Err("usage: always_entry ENTRY OUT.safetensors".into());
    };
    let entry: u8 = entry.parse().map_err(|e| format!("ENTRY {entry}: {e}"))?;
    let name = TargetAction::from_index(entry)
        .ok_or_else(|| format!("ENTRY {entry}: the menu has {N_TARGET_ACTIONS} entries"))?
        .name();
    // The smallest network: its output is the bias alone, in effect.
    let mut arch = ArchConfig::smappo();
    arch.d_model = 8;
    arch.heads = 2;
    arch.hidden = 8;
    arch.n_actions = N_TARGET_ACTIONS;
    arch.actions = ActionSpace::Targets;
    let mut actor = Actor::new(arch, 0);
    actor.add_action_bias(entry as usize, 1e4);
    // Behind the ORCA filter, as the bundled policy runs.
    let training = serde_json::json!({
        "train_config": { "orca_filter": true },
        "always_entry": name,
    });
    save_policy(std::path::Path::new(out), &actor, training)?;
    println!("wrote {out}: always \"{name}\" (entry {entry})");
    Ok(())
}
