//! Where machine time goes: for each ready part, how many steps it waits for a pick, split
//! by what the nearest part-less robot was doing meanwhile. Machine utilization (and so the
//! parts) is lost only in those steps, so this says which behaviour a better controller
//! would have to change (docs/RESULTS.md 7.8).
//!
//! Classes of a ready-part step at machine j:
//! - `first`: before j's first pick of the episode (robots still arriving);
//! - `at-box`: a part-less robot is within pick reach of j's box plus one step's travel
//!   (arriving, or held off by the safety margin);
//! - `en-route`: part-less robots exist, all of them farther than that (travel);
//! - `none-free`: every robot carries a part.
//!
//! Also: parts picked but still carried at the end (`stranded`), and for `en-route` steps
//! whether the matching (`plan::matching::matched_machine`, timed by the simulator's own
//! timers, which the planner's clock equals offline) sends a part-less robot to j, and
//! how many steps away that robot is (docs/RESULTS.md 7.13).
//!
//! Also for `en-route` steps: whether some part-less robot was parked at another, busy
//! machine, or left out of the matching altogether (a spare); and per machine cycle how
//! often the robot matched to it changed (RESULTS 7.15).
//!
//! cargo run --release -p learn --example machine_waits -- CHECKPOINT|greedy-orca SETUP [EPISODES] [SEED]
//! (`TRACE=1`: each late cycle's matched robot and its distance in steps, step by step, `s`
//! where it did not move; `SCENE=EPISODE,ROBOT,FROM,TO`: that robot's surroundings;
//! `FLOOR=grown`, `NEAREST=K`: a grown floor, the K nearest observed, docs/adr/0037)

use learn::eval::{run_episode_hooked, Method};
use sim::{ScenarioConfig, Setup};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(ck), Some(setup)) = (args.first(), args.get(1)) else {
        return Err("usage: machine_waits CHECKPOINT|greedy-orca SETUP [EPISODES] [SEED]".into());
    };
    let setup: Setup = setup.parse().map_err(|e| format!("SETUP {setup}: {e}"))?;
    let episodes: u64 = args.get(2).map_or(Ok(10), |s| s.parse())?;
    let seed: u64 = args.get(3).map_or(Ok(0), |s| s.parse())?;
    let ctrl = Method::script_or_filtered_checkpoint(ck)?;
    // FLOOR=grown and NEAREST=K: the grown floors and bounded observation of issue 46
    let mut cfg = ScenarioConfig::default();
    if std::env::var("FLOOR").as_deref() == Ok("grown") {
        cfg.world.floor = sim::Floor::Grown;
    }
    if let Ok(k) = std::env::var("NEAREST") {
        cfg.observation = obs::Bound::nearest(k.parse().map_err(|e| format!("NEAREST {k}: {e}"))?);
    }
    let mut c = Counts::default();
    let mut batch = obs::ObsBatch::default();
    let scene: Option<(u64, usize, u32, u32)> = std::env::var("SCENE").ok().and_then(|s| {
        let v: Vec<u64> = s.split(',').filter_map(|x| x.parse().ok()).collect();
        (v.len() == 4).then(|| (v[0], v[1] as usize, v[2] as u32, v[3] as u32))
    });
    for ep in 0..episodes {
        let mut picked_once: Vec<bool> = Vec::new();
        let mut last_ready: Vec<bool> = Vec::new();
        // the simulator's timers last step: one that went up is a pick, even of a part
        // picked on the step it appeared (its flag never rises)
        let mut last_timer: Vec<u32> = Vec::new();
        let mut final_carried = 0u64;
        // per machine: robot matched last step, switches since the last pick, late this cycle
        let mut cycle: Vec<(Option<usize>, u64, bool)> = Vec::new();
        // TRACE: per machine, this cycle's (matched robot, its steps away, has it a part)
        let trace = std::env::var_os("TRACE").is_some();
        let mut history: Vec<Vec<String>> = Vec::new();
        let mut t = 0u32;
        // last step's actions (TRACE) and positions, to mark robots asking for something
        // other than "matched" and robots that did not move
        let last_actions = std::cell::RefCell::new(Vec::<u8>::new());
        let mut last_pos: Vec<[f32; 2]> = Vec::new();
        let m = run_episode_hooked(
            &ctrl,
            &cfg,
            setup,
            seed,
            ep,
            |env| {
                let sizes = env.sizes();
                let near = sizes.robot_radius + sizes.reach + cfg.task.k_speed * cfg.world.dt;
                let machines: Vec<_> = env.machines().collect();
                let robots: Vec<_> = env.robots().collect();
                let step = cfg.task.k_speed * cfg.world.dt;
                let params = learn::baselines::fleet_params(sizes, &cfg).greedy_params();
                env.observe(&mut batch);
                let ready_in: Vec<Option<u32>> = machines
                    .iter()
                    .map(|m| Some(if m.part_ready { 0 } else { m.timer }))
                    .collect();
                let matched: Vec<Option<usize>> = (0..robots.len())
                    .map(|i| {
                        plan::matching::matched_machine(
                            batch.own_row(i),
                            batch.machines_row(i),
                            batch.peers_row(i),
                            &params,
                            &ready_in,
                        )
                    })
                    .collect();
                if picked_once.is_empty() {
                    picked_once = vec![false; machines.len()];
                    last_ready = vec![true; machines.len()];
                    last_timer = vec![0; machines.len()];
                }
                if cycle.is_empty() {
                    cycle = vec![(None, 0, false); machines.len()];
                    history = vec![Vec::new(); machines.len()];
                }
                t += 1;
                // SCENE=ep,robot,from,to: that robot's surroundings step by step
                if let Some((e, i, t0, t1)) = scene.filter(|s| s.0 == ep) {
                    if (t0..=t1).contains(&t) {
                        let act = last_actions.borrow().get(i).copied();
                        print_scene(e, t, i, &robots, &machines, matched[i], act);
                    }
                }
                for (j, m) in machines.iter().enumerate() {
                    let to_j = (0..robots.len()).find(|&i| matched[i] == Some(j));
                    let cy = &mut cycle[j];
                    if to_j.is_some() && cy.0.is_some() && to_j != cy.0 {
                        cy.1 += 1;
                    }
                    cy.0 = to_j;
                    if trace {
                        let r = to_j.map_or("-".to_string(), |i| {
                            let acts = last_actions.borrow();
                            let a = acts
                                .get(i)
                                .filter(|&&a| a != plan::targets::TargetAction::Matched as u8)
                                .and_then(|&a| plan::targets::TargetAction::from_index(a))
                                .map_or("", |a| a.name());
                            let still = last_pos.get(i).is_some_and(|q| {
                                plan::geom::norm([q[0] - robots[i].pos[0], q[1] - robots[i].pos[1]])
                                    < 0.1 * step
                            });
                            format!(
                                "r{i}@{:.0}{}{a}",
                                plan::geom::box_distance(m.centre, m.half, robots[i].pos) / step,
                                if still { "s" } else { "" }
                            )
                        });
                        history[j].push(format!("{}{r}", if m.part_ready { "R:" } else { "" }));
                    }
                    let in_reach = robots.iter().any(|r| {
                        !r.has_part && plan::geom::box_distance(m.centre, m.half, r.pos) <= near
                    });
                    if m.part_ready && !in_reach {
                        cy.2 = true;
                    }
                    let picked = !m.part_ready && (last_ready[j] || m.timer > last_timer[j]);
                    last_timer[j] = m.timer;
                    if picked {
                        if picked_once[j] {
                            if cy.2 {
                                if trace {
                                    println!("ep {ep} t {t} machine {j}: {}", history[j].join(" "));
                                }
                                c.late += 1;
                                c.switches_late += cy.1;
                            } else {
                                c.on_time += 1;
                                c.switches_on_time += cy.1;
                            }
                        }
                        *cy = (None, 0, false);
                        if trace {
                            history[j].clear();
                        }
                        picked_once[j] = true;
                    }
                    last_ready[j] = m.part_ready;
                    c.machine_steps += 1;
                    if !m.part_ready {
                        continue;
                    }
                    let class = if !picked_once[j] {
                        0
                    } else if robots.iter().all(|r| r.has_part) {
                        3
                    } else if in_reach {
                        1
                    } else {
                        2
                    };
                    c.waits[class] += 1;
                    if class == 2 {
                        c.en_route(&robots, &machines, &matched, near);
                    }
                    if let Some(i) = to_j.filter(|_| class == 2) {
                        c.heading += 1;
                        c.heading_steps +=
                            (plan::geom::box_distance(m.centre, m.half, robots[i].pos) / step)
                                as f64;
                    }
                }
                final_carried = robots.iter().filter(|r| r.has_part).count() as u64;
                let storages: Vec<_> = env.storages().collect();
                c.crawling(
                    &robots, &machines, &storages, &matched, &last_pos, near, step,
                );
                last_pos = robots.iter().map(|r| r.pos).collect();
                c.idle_steps += robots.iter().filter(|r| !r.has_part).count() as u64;
                c.robot_steps += robots.len() as u64;
            },
            |_, a| *last_actions.borrow_mut() = a.to_vec(),
        )?;
        c.parts += m.parts_delivered as u64;
        c.stranded += final_carried;
    }
    c.report(
        &format!("{setup} {ck} ({episodes} episodes, seed {seed})"),
        setup,
        episodes,
    );
    Ok(())
}

/// Totals over all episodes.
#[derive(Default)]
struct Counts {
    /// ready-part steps: [first, at-box, en-route, none-free]
    waits: [u64; 4],
    parts: u64,
    stranded: u64,
    machine_steps: u64,
    idle_steps: u64,
    /// robot-steps carrying or matched away from every box, and those moving < 1/3 step
    moving_steps: u64,
    crawl_steps: u64,
    robot_steps: u64,
    /// en-route steps with a robot matched to the machine, and that robot's distance in steps
    heading: u64,
    heading_steps: f64,
    /// en-route steps with a part-less robot parked at a busy machine (within `near` of it),
    /// the steps until that machine is ready summed, and with a part-less robot unmatched
    parked: u64,
    parked_wait: f64,
    spare: u64,
    /// per machine cycle (pick to the next robot in reach): how often the robot matched to
    /// it changed, split by whether a robot was in reach when the part became ready
    on_time: u64,
    late: u64,
    switches_on_time: u64,
    switches_late: u64,
}

impl Counts {
    /// An en-route step: is a part-less robot parked at another, busy machine, or unmatched?
    fn en_route(
        &mut self,
        robots: &[sim::RobotView],
        machines: &[sim::MachineView],
        matched: &[Option<usize>],
        near: f32,
    ) {
        let parked_soonest = robots
            .iter()
            .filter(|r| !r.has_part)
            .filter_map(|r| {
                machines.iter().find(|k| {
                    !k.part_ready && plan::geom::box_distance(k.centre, k.half, r.pos) <= near
                })
            })
            .map(|k| k.timer)
            .min();
        if let Some(w) = parked_soonest {
            self.parked += 1;
            self.parked_wait += w as f64;
        }
        if (0..robots.len()).any(|i| !robots[i].has_part && matched[i].is_none()) {
            self.spare += 1;
        }
    }

    /// Crawling: robots carrying or matched, away from every box, and moving less than a
    /// third of a full step.
    #[allow(clippy::too_many_arguments)]
    fn crawling(
        &mut self,
        robots: &[sim::RobotView],
        machines: &[sim::MachineView],
        storages: &[sim::StorageView],
        matched: &[Option<usize>],
        last_pos: &[[f32; 2]],
        near: f32,
        step: f32,
    ) {
        for (i, r) in robots.iter().enumerate() {
            let busy = r.has_part || matched[i].is_some();
            let away = machines
                .iter()
                .map(|m| plan::geom::box_distance(m.centre, m.half, r.pos))
                .chain(
                    storages
                        .iter()
                        .map(|s| plan::geom::box_distance(s.centre, s.half, r.pos)),
                )
                .all(|d| d > near);
            let slow = last_pos
                .get(i)
                .is_some_and(|q| plan::geom::norm([q[0] - r.pos[0], q[1] - r.pos[1]]) < step / 3.0);
            if busy && away {
                self.moving_steps += 1;
                if slow {
                    self.crawl_steps += 1;
                }
            }
        }
    }

    fn report(&self, label: &str, setup: Setup, episodes: u64) {
        let Counts {
            waits,
            parts,
            stranded,
            machine_steps,
            idle_steps,
            moving_steps,
            crawl_steps,
            robot_steps,
            heading,
            heading_steps,
            parked,
            parked_wait,
            spare,
            on_time,
            late,
            switches_on_time,
            switches_late,
        } = *self;
        let e = episodes as f64;
        let m = (setup.machines as f64) * e;
        println!(
            "{label}: parts {:.1}, stranded {:.2} per episode, robots part-less {:.1} % of steps",
            parts as f64 / e,
            stranded as f64 / e,
            100.0 * idle_steps as f64 / robot_steps.max(1) as f64
        );
        println!(
        "  ready-part steps per machine per episode: first {:.1}, at-box {:.1}, en-route {:.1}, none-free {:.1} (of {:.0} steps)",
        waits[0] as f64 / m,
        waits[1] as f64 / m,
        waits[2] as f64 / m,
        waits[3] as f64 / m,
        machine_steps as f64 / m
    );
        println!(
        "  en-route steps with a part-less robot matched to the machine: {:.1} % of them, that robot {:.1} steps from the box on average",
        100.0 * heading as f64 / waits[2].max(1) as f64,
        heading_steps / heading.max(1) as f64
    );
        println!(
        "  en-route steps with a part-less robot parked at a busy machine: {:.1} % (that machine ready in {:.1} steps, the soonest); with a part-less robot unmatched: {:.1} %",
        100.0 * parked as f64 / waits[2].max(1) as f64,
        parked_wait / parked.max(1) as f64,
        100.0 * spare as f64 / waits[2].max(1) as f64
    );
        println!(
        "  robots carrying or matched, away from every box: {:.1} % of robot-steps, {:.1} % of those moving less than a third of a step",
        100.0 * moving_steps as f64 / robot_steps.max(1) as f64,
        100.0 * crawl_steps as f64 / moving_steps.max(1) as f64
    );
        println!(
        "  machine cycles (pick to pick, after the first): {on_time} with a part-less robot in reach whenever the part was ready, {late} without; matched-robot changes per cycle: {:.2} / {:.2}",
        switches_on_time as f64 / on_time.max(1) as f64,
        switches_late as f64 / late.max(1) as f64
    );
    }
}

/// One step of robot `i`'s surroundings (SCENE): its nearest peers and the machines near it.
fn print_scene(
    e: u64,
    t: u32,
    i: usize,
    robots: &[sim::RobotView],
    machines: &[sim::MachineView],
    matched: Option<usize>,
    last_action: Option<u8>,
) {
    let r = &robots[i];
    let mut near_peers: Vec<(f32, usize)> = robots
        .iter()
        .enumerate()
        .filter(|&(k, _)| k != i)
        .map(|(k, q)| {
            (
                plan::geom::norm([q.pos[0] - r.pos[0], q.pos[1] - r.pos[1]]),
                k,
            )
        })
        .collect();
    near_peers.sort_by(|a, b| a.0.total_cmp(&b.0));
    let peers: Vec<String> = near_peers
        .iter()
        .take(4)
        .map(|(d, k)| format!("r{k}{} {d:.3}", if robots[*k].has_part { "*" } else { "" }))
        .collect();
    let boxes: Vec<String> = machines
        .iter()
        .enumerate()
        .map(|(j, m)| (j, plan::geom::box_distance(m.centre, m.half, r.pos)))
        .filter(|(_, d)| *d < 0.3)
        .map(|(j, d)| {
            format!(
                "m{j} {d:.3}{}",
                if machines[j].part_ready { "R" } else { "" }
            )
        })
        .collect();
    println!(
        "ep {e} t {t} r{i}{} at ({:.3}, {:.3}) matched {:?} act {:?} | peers {} | machines {}",
        if r.has_part { "*" } else { "" },
        r.pos[0],
        r.pos[1],
        matched,
        last_action,
        peers.join(", "),
        boxes.join(", ")
    );
}
