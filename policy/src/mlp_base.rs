//! MAPPO's MLP base: LayerNorm on the raw input (feature normalisation), then
//! [Linear -> ReLU -> LayerNorm] x 2 (layer_N = 1 in the reference implementation).

use nn::{relu, sized, Init, LayerNorm, LayerNormConfig, Linear, LinearConfig, ParamStore};
use rand::Rng;

#[derive(Debug, Clone, Copy)]
pub struct MlpBase {
    pub d_in: usize,
    pub hidden: usize,
    pub feat_ln: LayerNorm,
    pub fc: [Linear; 2],
    pub ln: [LayerNorm; 2],
}

#[derive(Debug, Clone, Default)]
pub struct MlpCache {
    pub(crate) n: usize,
    x0: Vec<f32>,
    pub(crate) m0: Vec<f32>,
    pub(crate) s0: Vec<f32>,
    pub(crate) act: [Vec<f32>; 2],
    m: [Vec<f32>; 2],
    s: [Vec<f32>; 2],
    ln_out: [Vec<f32>; 2],
    pub(crate) d_a: Vec<f32>,
    d_b: Vec<f32>,
    d_in: Vec<f32>,
    d_x: Vec<f32>,
    pub(crate) fac: crate::factored_cache::FactoredCache,
}

impl MlpCache {
    pub fn out(&self) -> &[f32] {
        &self.ln_out[1]
    }
}

impl MlpBase {
    pub fn new(
        d_in: usize,
        hidden: usize,
        store: &mut ParamStore,
        name: &str,
        rng: &mut impl Rng,
    ) -> Self {
        let feat_ln = LayerNorm::new(
            LayerNormConfig::new(d_in),
            store,
            &format!("{name}.feature_norm"),
        );
        let init = Init::Orthogonal {
            gain: std::f32::consts::SQRT_2,
        };
        let fc = [0, 1].map(|i| {
            let cfg = LinearConfig {
                d_in: if i == 0 { d_in } else { hidden },
                d_out: hidden,
                init,
            };
            Linear::new(cfg, store, &format!("{name}.fc{}", i + 1), rng)
        });
        let ln = [0, 1].map(|i| {
            LayerNorm::new(
                LayerNormConfig::new(hidden),
                store,
                &format!("{name}.ln{}", i + 1),
            )
        });
        Self {
            d_in,
            hidden,
            feat_ln,
            fc,
            ln,
        }
    }

    /// x: n x d_in -> c.out(): n x hidden.
    pub fn forward(&self, p: &[f32], x: &[f32], n: usize, c: &mut MlpCache) {
        c.n = n;
        let x0 = sized(&mut c.x0, n * self.d_in);
        self.feat_ln
            .forward(p, x, n, x0, sized(&mut c.m0, n), sized(&mut c.s0, n));
        let a = sized(&mut c.act[0], n * self.hidden);
        self.fc[0].forward(p, &c.x0, n, a);
        self.forward_tail(p, n, c);
    }

    /// From the first Linear's output (`c.act[0]`, pre-ReLU) to `c.out()`.
    pub(crate) fn forward_tail(&self, p: &[f32], n: usize, c: &mut MlpCache) {
        let h = self.hidden;
        for i in 0..2 {
            if i == 1 {
                let a = sized(&mut c.act[1], n * h);
                self.fc[1].forward(p, &c.ln_out[0], n, a);
            }
            relu::forward(&mut c.act[i]);
            let o = sized(&mut c.ln_out[i], n * h);
            self.ln[i].forward(
                p,
                &c.act[i],
                n,
                o,
                sized(&mut c.m[i], n),
                sized(&mut c.s[i], n),
            );
        }
    }

    /// Backward; the input gradient is not needed (raw observations).
    pub fn backward(&self, p: &[f32], g: &mut [f32], x: &[f32], c: &mut MlpCache, dout: &[f32]) {
        let n = c.n;
        self.backward_tail(p, g, c, dout);
        let dx0 = sized(&mut c.d_in, n * self.d_in);
        self.fc[0].backward(p, g, &c.x0, &c.d_a, n, Some(dx0), false);
        // feature norm (its gamma/beta are learnable; the input gradient is dropped)
        let dx = sized(&mut c.d_x, n * self.d_in);
        self.feat_ln.backward(p, g, x, &c.d_in, n, &c.m0, &c.s0, dx);
    }

    /// Backward from `dout` down to the first Linear's output: leaves dL/d`act[0]`
    /// (after the ReLU) in `c.d_a`.
    pub(crate) fn backward_tail(&self, p: &[f32], g: &mut [f32], c: &mut MlpCache, dout: &[f32]) {
        let (n, h) = (c.n, self.hidden);
        let da = sized(&mut c.d_a, n * h);
        let db = sized(&mut c.d_b, n * h);
        // layer 2
        self.ln[1].backward(p, g, &c.act[1], dout, n, &c.m[1], &c.s[1], da);
        relu::backward(&c.act[1], da);
        self.fc[1].backward(p, g, &c.ln_out[0], da, n, Some(db), false);
        // layer 1, down to the Linear's output
        self.ln[0].backward(p, g, &c.act[0], db, n, &c.m[0], &c.s[0], da);
        relu::backward(&c.act[0], da);
    }
}
