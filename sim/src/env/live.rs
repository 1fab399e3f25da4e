//! Robots, machines and storages joining and leaving during an episode.

use super::Env;
use crate::entities::{MachineId, RobotId, StaticBox, StorageId};
use crate::layout;
use crate::SimError;

impl Env {
    /// Add a robot at `pos`, or at a free spot drawn from the environment's rng.
    pub fn add_robot(&mut self, pos: Option<[f32; 2]>) -> Result<RobotId, SimError> {
        let boxes = self.all_boxes();
        let (room, r) = (self.cfg.world.room_size, self.sizes.robot_radius);
        let p = match pos {
            Some(p) => {
                let ok = p[0].is_finite()
                    && p[1].is_finite()
                    && layout::robot_fits(room, r, p, &boxes, &self.r_pos);
                if !ok {
                    return Err(SimError::BadPosition {
                        kind: "robot",
                        x: p[0],
                        y: p[1],
                    });
                }
                p
            }
            None => layout::sample_robot(&mut self.rng, room, r, &boxes, &self.r_pos).ok_or(
                SimError::NoFreeSpot {
                    kind: "robot",
                    tries: 4000,
                },
            )?,
        };
        let id = self.push_robot(p);
        self.grid.rebuild(&self.r_pos);
        Ok(id)
    }

    pub fn remove_robot(&mut self, id: RobotId) -> Result<(), SimError> {
        let i = self.robot_index(id).ok_or(SimError::UnknownId {
            kind: "robot",
            id: id.0,
        })?;
        // Ordered removal keeps the remaining robots' order (and so determinism).
        self.r_id.remove(i);
        self.r_pos.remove(i);
        self.r_vel.remove(i);
        self.r_prev.remove(i);
        self.r_force.remove(i);
        self.r_part.remove(i);
        self.r_reward.remove(i);
        self.r_events.remove(i);
        self.grid.rebuild(&self.r_pos);
        Ok(())
    }

    fn add_box(&mut self, machine: bool, pos: Option<[f32; 2]>) -> Result<u32, SimError> {
        let kind = if machine { "machine" } else { "storage" };
        let half = if machine {
            self.sizes.machine_half
        } else {
            self.sizes.storage_half
        };
        let boxes = self.all_boxes();
        let room = self.cfg.world.room_size;
        let gap = self.cfg.sizes.box_gap_diameters * 2.0 * self.sizes.robot_radius;
        let r = self.sizes.robot_radius;
        let b = match pos {
            Some(c) => {
                let b = StaticBox { centre: c, half };
                let clear = self
                    .r_pos
                    .iter()
                    .all(|&p| b.signed_distance(p).0 > r * 1.25);
                let ok = c[0].is_finite()
                    && c[1].is_finite()
                    && clear
                    && layout::box_fits(room, gap, &b, &boxes);
                if !ok {
                    return Err(SimError::BadPosition {
                        kind,
                        x: c[0],
                        y: c[1],
                    });
                }
                b
            }
            None => layout::sample_box(&mut self.rng, room, gap, half, &boxes, &self.r_pos, r)
                .ok_or(SimError::NoFreeSpot { kind, tries: 4000 })?,
        };
        Ok(if machine {
            self.push_machine(b.centre).0
        } else {
            self.push_storage(b.centre).0
        })
    }

    pub fn add_machine(&mut self, pos: Option<[f32; 2]>) -> Result<MachineId, SimError> {
        let id = self.add_box(true, pos).map(MachineId)?;
        self.update_p_max();
        Ok(id)
    }

    pub fn add_storage(&mut self, pos: Option<[f32; 2]>) -> Result<StorageId, SimError> {
        self.add_box(false, pos).map(StorageId)
    }

    pub fn remove_machine(&mut self, id: MachineId) -> Result<(), SimError> {
        let j = self
            .m_id
            .iter()
            .position(|&m| m == id)
            .ok_or(SimError::UnknownId {
                kind: "machine",
                id: id.0,
            })?;
        self.p_max_removed += self.machine_p_max(self.m_alive[j]);
        self.m_id.remove(j);
        self.m_box.remove(j);
        self.m_ready.remove(j);
        self.m_timer.remove(j);
        self.m_alive.remove(j);
        self.update_p_max();
        Ok(())
    }

    pub fn remove_storage(&mut self, id: StorageId) -> Result<(), SimError> {
        let k = self
            .s_id
            .iter()
            .position(|&s| s == id)
            .ok_or(SimError::UnknownId {
                kind: "storage",
                id: id.0,
            })?;
        self.s_id.remove(k);
        self.s_box.remove(k);
        Ok(())
    }
}
