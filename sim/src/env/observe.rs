//! Observations: each robot's view of the entity sets (the `obs` crate's layout), every
//! entity (the paper's) or the k nearest of each group (`ScenarioConfig::observation`).

use super::Env;

impl Env {
    /// The entity counts every robot's observation has now.
    pub fn obs_counts(&self) -> obs::Counts {
        let o = &self.cfg.observation;
        let n = self.r_id.len();
        obs::Counts {
            machines: obs::Bound::observed(o.nearest_machines, self.m_id.len()),
            storages: obs::Bound::observed(o.nearest_storages, self.s_id.len()),
            peers: obs::Bound::observed(o.nearest_peers, n.saturating_sub(1)),
        }
    }

    /// Write every robot's observation (rows in robot order) into the given slices, sized
    /// for `obs_counts()`: own n x 3, machines n x M' x 3, storages n x K' x 2, peers
    /// n x P' x 3 (M' = M, K' = K, P' = n - 1 unless the observation is bounded).
    pub fn observe_into(
        &self,
        own: &mut [f32],
        machines: &mut [f32],
        storages: &mut [f32],
        peers: &mut [f32],
    ) {
        if self.cfg.observation.is_bounded() {
            return self.observe_nearest(own, machines, storages, peers);
        }
        let n = self.r_id.len();
        let (m, k) = (self.m_id.len(), self.s_id.len());
        let pw = n.saturating_sub(1) * 3;
        for i in 0..n {
            let [x, y] = self.r_pos[i];
            own[i * 3..i * 3 + 3].copy_from_slice(&[x, y, obs::flag(self.r_part[i])]);
            let mo = &mut machines[i * m * 3..(i + 1) * m * 3];
            for j in 0..m {
                let c = self.m_box[j].centre;
                mo[j * 3] = c[0] - x;
                mo[j * 3 + 1] = c[1] - y;
                mo[j * 3 + 2] = obs::flag(self.m_ready[j]);
            }
            let so = &mut storages[i * k * 2..(i + 1) * k * 2];
            for j in 0..k {
                let c = self.s_box[j].centre;
                so[j * 2] = c[0] - x;
                so[j * 2 + 1] = c[1] - y;
            }
            let po = &mut peers[i * pw..(i + 1) * pw];
            // Peers in robot order without robot i: two straight runs, no per-item branch.
            let (before, after) = po.split_at_mut(i * 3);
            for (o, (q, &hp)) in before
                .chunks_exact_mut(3)
                .zip(self.r_pos[..i].iter().zip(&self.r_part[..i]))
            {
                o[0] = q[0] - x;
                o[1] = q[1] - y;
                o[2] = obs::flag(hp);
            }
            for (o, (q, &hp)) in after
                .chunks_exact_mut(3)
                .zip(self.r_pos[i + 1..].iter().zip(&self.r_part[i + 1..]))
            {
                o[0] = q[0] - x;
                o[1] = q[1] - y;
                o[2] = obs::flag(hp);
            }
        }
    }

    /// [`Self::observe_into`] with the k nearest entities of each bounded group, listed in
    /// the group's own order (so k >= the group's size gives the unbounded observation).
    /// Each group is put in a grid ([`obs::nearest::Grid`]) once per call and each robot's
    /// query visits only the cells around it, so a robot's cost is bounded by its
    /// neighbourhood, not the floor; the rule is robot_node's (`obs::nearest`).
    fn observe_nearest(
        &self,
        own: &mut [f32],
        machines: &mut [f32],
        storages: &mut [f32],
        peers: &mut [f32],
    ) {
        let c = self.obs_counts();
        let o = self.cfg.observation;
        let n = self.r_id.len();
        let m_centres: Vec<[f32; 2]> = self.m_box.iter().map(|b| b.centre).collect();
        let s_centres: Vec<[f32; 2]> = self.s_box.iter().map(|b| b.centre).collect();
        let mut grids = [
            obs::nearest::Grid::default(),
            obs::nearest::Grid::default(),
            obs::nearest::Grid::default(),
        ];
        grids[0].build(&m_centres);
        grids[1].build(&s_centres);
        grids[2].build(&self.r_pos);
        let mut pick = Vec::new();
        for i in 0..n {
            let p = self.r_pos[i];
            own[i * 3..i * 3 + 3].copy_from_slice(&[p[0], p[1], obs::flag(self.r_part[i])]);
            let mo = &mut machines[i * c.machines * 3..(i + 1) * c.machines * 3];
            grids[0].select(p, o.nearest_machines, None, &mut pick);
            for (slot, &j) in pick.iter().enumerate() {
                let q = m_centres[j];
                mo[slot * 3..slot * 3 + 3].copy_from_slice(&[
                    q[0] - p[0],
                    q[1] - p[1],
                    obs::flag(self.m_ready[j]),
                ]);
            }
            let so = &mut storages[i * c.storages * 2..(i + 1) * c.storages * 2];
            grids[1].select(p, o.nearest_storages, None, &mut pick);
            for (slot, &j) in pick.iter().enumerate() {
                let q = s_centres[j];
                so[slot * 2..slot * 2 + 2].copy_from_slice(&[q[0] - p[0], q[1] - p[1]]);
            }
            let po = &mut peers[i * c.peers * 3..(i + 1) * c.peers * 3];
            grids[2].select(p, o.nearest_peers, Some(i), &mut pick);
            for (slot, &j) in pick.iter().enumerate() {
                let q = self.r_pos[j];
                po[slot * 3..slot * 3 + 3].copy_from_slice(&[
                    q[0] - p[0],
                    q[1] - p[1],
                    obs::flag(self.r_part[j]),
                ]);
            }
        }
    }

    /// Every robot's observation as a batch (resized in place; no allocation once sized).
    pub fn observe(&self, out: &mut obs::ObsBatch) {
        out.resize(self.r_id.len(), self.obs_counts());
        let obs::ObsBatch {
            own,
            machines,
            storages,
            peers,
            ..
        } = out;
        self.observe_into(own, machines, storages, peers);
    }
}
