//! Commands typed on stdin while a fleet runs (docs/bench/live.md).

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
