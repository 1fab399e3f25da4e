//! Commands typed on stdin while a fleet runs (docs/bench/live.md): parsed, then applied
//! to the running [`Fleet`].

use std::io::Write;

use super::children::{restarts_summary, signal, wait_or_kill, STOP_GRACE};
use super::{Fleet, BRIDGE};

/// A command typed while the fleet runs (see the module docs).
#[derive(Debug, PartialEq)]
pub enum LiveCmd {
    AddRobot(Option<String>),
    Kill(String),
    Stop(String),
    /// A line for the bridge's `/tending/command` language.
    Bridge(String),
    Status,
}

pub fn parse_live(line: &str) -> Result<LiveCmd, String> {
    let w: Vec<&str> = line.split_whitespace().collect();
    let num = |s: &str| -> Result<(), String> {
        s.parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .map(|_| ())
            .ok_or_else(|| format!("bad number `{s}`"))
    };
    let pos = |rest: &[&str]| -> Result<String, String> {
        match rest {
            [] => Ok(String::new()),
            [x, y] => {
                num(x)?;
                num(y)?;
                Ok(format!(" {x} {y}"))
            }
            _ => Err("expected no position or `X Y`".into()),
        }
    };
    let robot_name = |n: &str| -> Result<String, String> {
        let n = n.trim_start_matches('/');
        if !n.is_empty()
            && !n.as_bytes()[0].is_ascii_digit()
            && n.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
            && !n.starts_with("machine_")
            && !n.starts_with("storage_")
        {
            Ok(n.to_string())
        } else {
            Err(format!("bad robot name `{n}`"))
        }
    };
    match w.as_slice() {
        ["add", "robot"] => Ok(LiveCmd::AddRobot(None)),
        ["add", "robot", n] => Ok(LiveCmd::AddRobot(Some(robot_name(n)?))),
        ["kill", n] | ["remove", "robot", n] => Ok(LiveCmd::Kill(robot_name(n)?)),
        ["stop", n] => Ok(LiveCmd::Stop(robot_name(n)?)),
        ["add", "machine", rest @ ..] => Ok(LiveCmd::Bridge(format!("add_machine{}", pos(rest)?))),
        ["add", "storage", rest @ ..] => Ok(LiveCmd::Bridge(format!("add_storage{}", pos(rest)?))),
        ["remove", "machine", id] => id
            .parse::<u32>()
            .map(|i| LiveCmd::Bridge(format!("remove_machine {i}")))
            .map_err(|_| format!("bad id `{id}`")),
        ["remove", "storage", id] => id
            .parse::<u32>()
            .map(|i| LiveCmd::Bridge(format!("remove_storage {i}")))
            .map_err(|_| format!("bad id `{id}`")),
        ["status"] => Ok(LiveCmd::Status),
        _ => Err(format!(
            "unknown command `{line}` (add robot [NAME] | kill NAME | stop NAME | add machine [X Y] | remove machine ID | add storage [X Y] | remove storage ID | status)"
        )),
    }
}

/// The commands applied to the running fleet.
impl Fleet {
    pub(super) fn on_command(&mut self, line: &str) {
        if line.is_empty() {
            return;
        }
        let at = self.at();
        match parse_live(line) {
            Err(e) => println!("fleet: t={at:.1}s error: {e}"),
            Ok(LiveCmd::AddRobot(name)) => self.add_robot(name),
            Ok(LiveCmd::Kill(name)) => self.remove_robot(&name, libc::SIGKILL),
            Ok(LiveCmd::Stop(name)) => self.remove_robot(&name, libc::SIGINT),
            Ok(LiveCmd::Bridge(l)) => {
                match writeln!(self.bridge.stdin, "{l}").and_then(|_| self.bridge.stdin.flush()) {
                    Ok(()) => println!("fleet: t={at:.1}s sent `{l}` to {BRIDGE}"),
                    Err(e) => println!("fleet: t={at:.1}s error: {BRIDGE} stdin: {e}"),
                }
            }
            Ok(LiveCmd::Status) => {
                let procs: Vec<String> = self
                    .robots
                    .iter()
                    .map(|p| format!("{}({})", p.label, p.child.id()))
                    .chain([format!("{BRIDGE}({})", self.bridge.child.id())])
                    .collect();
                println!(
                    "fleet: t={at:.1}s status: {} robots in {} processes: {}; health: {}; watchdog restarts: {}",
                    self.robots.iter().map(|p| p.robots.len()).sum::<usize>(),
                    procs.len(),
                    procs.join(" "),
                    self.health.status(),
                    restarts_summary(&self.restarts)
                );
                if let Some(v) = &self.last {
                    println!("fleet: last metrics {v}");
                }
            }
        }
    }

    fn hosts(&self, name: &str) -> bool {
        self.robots
            .iter()
            .any(|p| p.robots.iter().any(|r| r == name))
    }

    fn add_robot(&mut self, name: Option<String>) {
        let at = self.at();
        let name = name.unwrap_or_else(|| loop {
            let n = format!("robot_{}", self.next_robot);
            self.next_robot += 1;
            if !self.hosts(&n) {
                break n;
            }
        });
        if self.hosts(&name) || name == BRIDGE {
            println!("fleet: t={at:.1}s error: {name} is already running");
            return;
        }
        match self.plan.spawn_robots(std::slice::from_ref(&name), false) {
            Ok(p) => {
                println!("fleet: t={at:.1}s started {name} (pid {})", p.child.id());
                self.robots.push(p);
            }
            Err(e) => println!("fleet: t={at:.1}s error: {e:#}"),
        }
    }

    /// Signal the process hosting `name`; a group process is restarted without it.
    fn remove_robot(&mut self, name: &str, sig: i32) {
        let at = self.at();
        let what = if sig == libc::SIGKILL {
            "SIGKILL"
        } else {
            "SIGINT"
        };
        if name == BRIDGE {
            println!("fleet: t={at:.1}s error: the bridge is not a robot");
            return;
        }
        let Some(i) = self
            .robots
            .iter()
            .position(|p| p.robots.iter().any(|r| r == name))
        else {
            println!("fleet: t={at:.1}s error: no running robot `{name}`");
            return;
        };
        let mut p = self.robots.remove(i);
        signal(p.child.id(), sig);
        let st = if sig == libc::SIGKILL {
            p.child.wait().ok()
        } else {
            wait_or_kill(&mut p.child, STOP_GRACE)
        };
        println!(
            "fleet: t={at:.1}s {what} {} (pid {}): {}",
            p.label,
            p.child.id(),
            st.map(|s| s.to_string()).unwrap_or("killed".into())
        );
        let rest: Vec<String> = p.robots.into_iter().filter(|r| r != name).collect();
        if rest.is_empty() {
            return;
        }
        match self.plan.spawn_robots(&rest, true) {
            Ok(q) => {
                println!(
                    "fleet: t={at:.1}s restarted {} without {name} (pid {})",
                    q.label,
                    q.child.id()
                );
                self.robots.push(q);
            }
            Err(e) => self.failure = Some(format!("restarting {} failed: {e:#}", rest.join(","))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn live_commands_parse() {
        assert_eq!(parse_live("add robot"), Ok(LiveCmd::AddRobot(None)));
        assert_eq!(
            parse_live("add robot rover_1"),
            Ok(LiveCmd::AddRobot(Some("rover_1".into())))
        );
        assert_eq!(
            parse_live("kill /robot_3"),
            Ok(LiveCmd::Kill("robot_3".into()))
        );
        assert_eq!(
            parse_live("stop robot_3"),
            Ok(LiveCmd::Stop("robot_3".into()))
        );
        assert_eq!(
            parse_live("add machine"),
            Ok(LiveCmd::Bridge("add_machine".into()))
        );
        assert_eq!(
            parse_live("add machine 0.5 -0.25"),
            Ok(LiveCmd::Bridge("add_machine 0.5 -0.25".into()))
        );
        assert_eq!(
            parse_live("remove machine 2"),
            Ok(LiveCmd::Bridge("remove_machine 2".into()))
        );
        assert_eq!(
            parse_live("add storage"),
            Ok(LiveCmd::Bridge("add_storage".into()))
        );
        assert_eq!(
            parse_live("remove storage 1"),
            Ok(LiveCmd::Bridge("remove_storage 1".into()))
        );
        assert_eq!(parse_live("status"), Ok(LiveCmd::Status));
        for bad in [
            "add machine 1",
            "add machine nan 0",
            "remove machine x",
            "kill 3robot",
            "kill machine_0",
            "fly",
        ] {
            assert!(parse_live(bad).is_err(), "{bad}");
        }
    }
}
