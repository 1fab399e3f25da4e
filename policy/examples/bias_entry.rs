//! A copy of a target-action checkpoint with `DELTA` added to one menu entry's output bias:
//! a start for a fine-tune in which the policy should try an entry it has all but stopped
//! choosing (docs/RESULTS.md 7.9: "matched" for robots with a part, after that entry's
//! storage rule changed). The training metadata is kept, with the change noted in it.
//!
//! cargo run --release -p policy --example bias_entry -- CHECKPOINT ENTRY DELTA OUT.safetensors

use plan::targets::TargetAction;
use policy::{checkpoint::save_policy, ActionSpace, Policy};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [ck, entry, delta, out] = args.as_slice() else {
        return Err("usage: bias_entry CHECKPOINT ENTRY DELTA OUT.safetensors".into());
    };
    let pol = Policy::load(ck)?;
    let mut actor = pol.actor().clone();
    if actor.arch.actions != ActionSpace::Targets {
        return Err(format!("CHECKPOINT {ck}: not a target-action policy").into());
    }
    let entry: u8 = entry.parse().map_err(|e| format!("ENTRY {entry}: {e}"))?;
    let name = TargetAction::from_index(entry)
        .filter(|_| (entry as usize) < actor.arch.n_actions)
        .ok_or_else(|| format!("ENTRY {entry}: {ck} has {} entries", actor.arch.n_actions))?
        .name();
    let delta: f32 = delta.parse().map_err(|e| format!("DELTA {delta}: {e}"))?;
    if !delta.is_finite() {
        return Err(format!("DELTA {delta}: not finite").into());
    }
    actor.add_action_bias(entry as usize, delta);
    let mut training = pol.meta().training.clone();
    if let Some(t) = training.as_object_mut() {
        t.insert(
            "bias_entry".into(),
            serde_json::json!({ "from": ck, "entry": name, "delta": delta }),
        );
    }
    save_policy(std::path::Path::new(out), &actor, training)?;
    println!("wrote {out}: {ck} with {delta:+} on \"{name}\" (entry {entry})");
    Ok(())
}
