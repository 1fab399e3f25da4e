//! The recurrent tail shared by actors and critics: GRU -> LayerNorm -> Linear.

use nn::{
    sized, Gru, GruCache, GruConfig, Init, LayerNorm, LayerNormConfig, Linear, LinearConfig,
    ParamStore,
};
use rand::Rng;

#[derive(Debug, Clone, Copy)]
pub struct RecurrentHead {
    pub gru: Gru,
    pub ln: LayerNorm,
    pub out: Linear,
}

#[derive(Debug, Clone, Default)]
pub struct HeadCache {
    pub gru: GruCache,
    /// GRU hidden state after every step: (T*B) x H.
    pub h: Vec<f32>,
    z: Vec<f32>,
    mean: Vec<f32>,
    rstd: Vec<f32>,
    /// Output: (T*B) x d_out.
    pub y: Vec<f32>,
    dz: Vec<f32>,
    dh: Vec<f32>,
}

impl RecurrentHead {
    /// `out_name`: "action_out" or "value_out"; `gain`: 0.01 for the action head (MAPPO).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        d_in: usize,
        hidden: usize,
        d_out: usize,
        gain: f32,
        out_name: &str,
        store: &mut ParamStore,
        rng: &mut impl Rng,
    ) -> Self {
        let gru = Gru::new(GruConfig { d_in, hidden }, store, "gru", rng);
        let ln = LayerNorm::new(LayerNormConfig::new(hidden), store, "gru_ln");
        let out = Linear::new(
            LinearConfig {
                d_in: hidden,
                d_out,
                init: Init::Orthogonal { gain },
            },
            store,
            out_name,
            rng,
        );
        Self { gru, ln, out }
    }

    #[allow(clippy::too_many_arguments)]
    pub fn forward(
        &self,
        p: &[f32],
        x: &[f32],
        t: usize,
        b: usize,
        h0: &[f32],
        masks: &[f32],
        c: &mut HeadCache,
    ) {
        let (hd, n) = (self.gru.cfg.hidden, t * b);
        let h = sized(&mut c.h, n * hd);
        self.gru.forward(p, x, t, b, h0, masks, &mut c.gru, h);
        let z = sized(&mut c.z, n * hd);
        self.ln
            .forward(p, h, n, z, sized(&mut c.mean, n), sized(&mut c.rstd, n));
        let y = sized(&mut c.y, n * self.out.cfg.d_out);
        self.out.forward(p, z, n, y);
    }

    /// Backward from dy ((T*B) x d_out); writes dx ((T*B) x d_in).
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        p: &[f32],
        g: &mut [f32],
        x: &[f32],
        t: usize,
        b: usize,
        c: &mut HeadCache,
        dy: &[f32],
        dx: &mut [f32],
    ) {
        let (hd, n) = (self.gru.cfg.hidden, t * b);
        let dz = sized(&mut c.dz, n * hd);
        self.out.backward(p, g, &c.z, dy, n, Some(dz), false);
        let dh = sized(&mut c.dh, n * hd);
        self.ln.backward(p, g, &c.h, dz, n, &c.mean, &c.rstd, dh);
        self.gru.backward(p, g, x, t, b, &mut c.gru, dh, dx, None);
    }

    /// Hidden state after the last step of the last forward (B x H).
    pub fn last_hidden<'a>(&self, c: &'a HeadCache, t: usize, b: usize) -> &'a [f32] {
        let hd = self.gru.cfg.hidden;
        &c.h[(t - 1) * b * hd..t * b * hd]
    }
}
