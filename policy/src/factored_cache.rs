//! Buffers of the factored first layer (`factored_input`), kept in the MLP base's cache
//! (`mlp_base::MlpCache`): their own file so neither of those two files imports the other
//! both ways.

/// Buffers of the factored first layer.
#[derive(Debug, Clone, Default)]
pub struct FactoredCache {
    /// gamma . own (rows x d_own)
    pub(crate) g_own: Vec<f32>,
    /// gamma . shared (groups x d_sh)
    pub(crate) g_sh: Vec<f32>,
    /// W_sh (gamma . shared) per group (groups x hidden)
    pub(crate) sh_out: Vec<f32>,
    /// W gamma, W beta + b (hidden each)
    pub(crate) w_gamma: Vec<f32>,
    pub(crate) w_beta: Vec<f32>,
    // backward
    pub(crate) xhat_own: Vec<f32>,
    pub(crate) d_own: Vec<f32>,
    pub(crate) u_group: Vec<f32>,
    pub(crate) u_mu: Vec<f32>,
    pub(crate) da_sum: Vec<f32>,
    pub(crate) t_sh: Vec<f32>,
    pub(crate) dcol: Vec<f32>,
}
