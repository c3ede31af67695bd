//! Seeded, backend-independent weight initialisation.
//!
//! burn seeds its random numbers per backend and process-wide (two runs in one process, or
//! the CPU and a GPU, would start from different weights). mdrlat draws every initial weight
//! from its own value-stable RNG instead, with PyTorch's default law for linear and
//! convolution layers — U(−1/√fan_in, 1/√fan_in) for weights and biases — so the same seed
//! gives the same network on every backend and in every thread. Parameter ids are numbered
//! in traversal order too (burn draws them at random per process), so that two runs with one
//! seed write the same checkpoint bytes: the ids are stored with the weights and key the
//! optimiser's state.

use burn::module::{ModuleMapper, Param, ParamId};
use burn::prelude::*;
use mdrlat_core::Rng;

/// Replaces every float parameter, in traversal order, with seeded uniform values.
pub(crate) struct SeededInit {
    rng: Rng,
    /// fan-in of the last weight seen: the bias that follows it uses the same bound.
    fan_in: usize,
    /// Parameters numbered so far.
    count: u64,
}

impl SeededInit {
    pub(crate) fn new(seed: u64) -> Self {
        Self { rng: Rng::derive(seed, 0x1417), fan_in: 1, count: 0 }
    }
}

impl ModuleMapper for SeededInit {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        self.count += 1;
        // A fixed, recognisable range: "mdrl" then the parameter's position.
        let id = ParamId::from(0x6d64_726c_0000_0000 | self.count);
        let (_, old, mapper) = param.consume();
        let fresh = {
            let dims = old.dims();
            // Linear weights are [d_in, d_out]; conv weights [out, in, k...]; biases [out].
            self.fan_in = match D {
                1 => self.fan_in,
                2 => dims[0],
                _ => dims[1..].iter().product(),
            };
            let bound = 1.0 / (self.fan_in.max(1) as f32).sqrt();
            let n: usize = dims.iter().product();
            let values: Vec<f32> = (0..n).map(|_| self.rng.range_f32(-bound, bound)).collect();
            let fresh = Tensor::<D>::from_data(TensorData::new(values, dims), &old.device());
            if old.is_require_grad() { fresh.require_grad() } else { fresh }
        };
        Param::from_mapped_value(id, fresh, mapper)
    }
}
