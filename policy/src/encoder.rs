//! SMAPPO's input-size invariant observation encoder (paper Fig. 1):
//! one Linear+ReLU encoder per entity type to d; one MHA per group (machines, storages,
//! peers) with the robot's own embedding as the query; concat [self, att_m, att_s, att_p]
//! (4d) -> Linear -> Tanh -> LayerNorm. Any counts work, including 0 of a group.
//! The entity embeddings are never stored for the whole batch: the attention computes
//! each row's from the raw features ([`Kv::Encoded`]).

use nn::{
    relu, sized, tanh, Init, Kv, LayerNorm, LayerNormConfig, Linear, LinearConfig, MhaCache,
    MhaConfig, MultiHeadAttention, ParamStore,
};
use obs::{ObsBatch, MACHINE_DIM, PEER_DIM, SELF_DIM, STORAGE_DIM};
use rand::Rng;

#[derive(Debug, Clone, Copy)]
pub struct SmappoEncoder {
    pub d: usize,
    pub out_dim: usize,
    pub self_enc: Linear,
    pub ent_enc: [Linear; 3],
    pub att: [MultiHeadAttention; 3],
    pub fc: Linear,
    pub ln: LayerNorm,
}

/// Activations and gradient scratch of one encoder.
#[derive(Debug, Clone, Default)]
pub struct EncoderCache {
    n: usize,
    s: [usize; 3],
    e_self: Vec<f32>,
    att_out: [Vec<f32>; 3],
    att: [MhaCache; 3],
    cat: Vec<f32>,
    fc: Vec<f32>,
    mean: Vec<f32>,
    rstd: Vec<f32>,
    pub out: Vec<f32>,
    d_fc: Vec<f32>,
    d_cat: Vec<f32>,
    d_self: Vec<f32>,
    d_att: Vec<f32>,
}

const GROUPS: [&str; 3] = ["machines", "storages", "peers"];
const DIMS: [usize; 3] = [MACHINE_DIM, STORAGE_DIM, PEER_DIM];

fn group(obs: &ObsBatch, k: usize) -> (&[f32], usize) {
    match k {
        0 => (&obs.machines, obs.counts.machines),
        1 => (&obs.storages, obs.counts.storages),
        _ => (&obs.peers, obs.counts.peers),
    }
}

impl SmappoEncoder {
    pub fn new(
        d: usize,
        heads: usize,
        out_dim: usize,
        store: &mut ParamStore,
        name: &str,
        rng: &mut impl Rng,
    ) -> Self {
        let relu_init = Init::Orthogonal {
            gain: std::f32::consts::SQRT_2,
        };
        let lin = |d_in, d_out, init, store: &mut ParamStore, n: &str, rng: &mut _| {
            Linear::new(
                LinearConfig { d_in, d_out, init },
                store,
                &format!("{name}.{n}"),
                rng,
            )
        };
        let self_enc = lin(SELF_DIM, d, relu_init, store, "self_enc", rng);
        let ent_enc = [0, 1, 2].map(|k| {
            lin(
                DIMS[k],
                d,
                relu_init,
                store,
                &format!("{}_enc", GROUPS[k]),
                rng,
            )
        });
        let att = [0, 1, 2].map(|k| {
            MultiHeadAttention::new(
                MhaConfig { dim: d, heads },
                store,
                &format!("{name}.att_{}", GROUPS[k]),
                rng,
            )
        });
        let fc = lin(
            4 * d,
            out_dim,
            Init::Orthogonal { gain: 5.0 / 3.0 },
            store,
            "fc",
            rng,
        );
        let ln = LayerNorm::new(LayerNormConfig::new(out_dim), store, &format!("{name}.ln"));
        Self {
            d,
            out_dim,
            self_enc,
            ent_enc,
            att,
            fc,
            ln,
        }
    }

    /// Encodes every row of `obs` into `c.out` (rows x out_dim).
    pub fn forward(&self, p: &[f32], obs: &ObsBatch, c: &mut EncoderCache) {
        let (n, d) = (obs.rows, self.d);
        c.n = n;
        let e_self = sized(&mut c.e_self, n * d);
        self.self_enc.forward(p, &obs.own, n, e_self);
        relu::forward(e_self);
        let cat = sized(&mut c.cat, n * 4 * d);
        for r in 0..n {
            cat[r * 4 * d..r * 4 * d + d].copy_from_slice(&e_self[r * d..(r + 1) * d]);
        }
        for k in 0..3 {
            let (x, s) = group(obs, k);
            c.s[k] = s;
            // the entity embeddings are computed inside the attention, row by row
            let kv = Kv::Encoded {
                x,
                enc: &self.ent_enc[k],
            };
            let ao = sized(&mut c.att_out[k], n * d);
            self.att[k].forward(p, e_self, kv, n, s, &mut c.att[k], ao);
            for r in 0..n {
                let o = r * 4 * d + (k + 1) * d;
                cat[o..o + d].copy_from_slice(&ao[r * d..(r + 1) * d]);
            }
        }
        let od = self.out_dim;
        let fc = sized(&mut c.fc, n * od);
        self.fc.forward(p, cat, n, fc);
        tanh::forward(fc);
        let (mean, rstd) = (sized(&mut c.mean, n), sized(&mut c.rstd, n));
        let out = sized(&mut c.out, n * od);
        self.ln.forward(p, fc, n, out, mean, rstd);
    }

    /// Backward of the last [`forward`](Self::forward) on the same `obs`.
    pub fn backward(
        &self,
        p: &[f32],
        g: &mut [f32],
        obs: &ObsBatch,
        c: &mut EncoderCache,
        dout: &[f32],
    ) {
        let (n, d, od) = (c.n, self.d, self.out_dim);
        let d_fc = sized(&mut c.d_fc, n * od);
        self.ln
            .backward(p, g, &c.fc, dout, n, &c.mean, &c.rstd, d_fc);
        tanh::backward(&c.fc, d_fc);
        let d_cat = sized(&mut c.d_cat, n * 4 * d);
        self.fc.backward(p, g, &c.cat, d_fc, n, Some(d_cat), false);
        let d_self = sized(&mut c.d_self, n * d);
        for r in 0..n {
            d_self[r * d..(r + 1) * d].copy_from_slice(&d_cat[r * 4 * d..r * 4 * d + d]);
        }
        for k in 0..3 {
            let s = c.s[k];
            let d_att = sized(&mut c.d_att, n * d);
            for r in 0..n {
                let o = r * 4 * d + (k + 1) * d;
                d_att[r * d..(r + 1) * d].copy_from_slice(&d_cat[o..o + d]);
            }
            let (x, _) = group(obs, k);
            let kv = Kv::Encoded {
                x,
                enc: &self.ent_enc[k],
            };
            self.att[k].backward(
                p,
                g,
                &c.e_self,
                kv,
                n,
                s,
                &mut c.att[k],
                d_att,
                d_self,
                None,
            );
        }
        relu::backward(&c.e_self, d_self);
        self.self_enc
            .backward(p, g, &obs.own, d_self, n, None, false);
    }
}
