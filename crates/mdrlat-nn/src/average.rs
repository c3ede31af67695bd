//! Averages of networks' weights: the mean of several checkpoints (`mdrlat export
//! --checkpoint A --checkpoint B …`) and the running average a run can keep of its online
//! network (`train.average_horizon`). Successive weights of one run lie in one basin, and
//! their mean is a steadier policy than any one of them (SWA, Polyak averaging).

use crate::net::QNet;
use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::prelude::*;

/// Every float parameter's values and shape, in visiting order.
struct Collect(Vec<(Vec<usize>, Vec<f32>)>);

impl ModuleVisitor for Collect {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let t = param.val();
        self.0.push((t.dims().to_vec(), t.into_data().iter::<f32>().collect()));
    }
}

/// Replaces each float parameter, in visiting order, by the next of `values` (its id kept).
struct Replace(std::vec::IntoIter<Vec<f32>>);

impl ModuleMapper for Replace {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let (id, old, mapper) = param.consume();
        let dims = old.dims();
        let values = self.0.next().expect("one value list per parameter (counted before)");
        let t = Tensor::<D>::from_data(TensorData::new(values, dims), &old.device());
        Param::from_mapped_value(id, t, mapper)
    }
}

impl QNet {
    /// Every float parameter's values, flattened in visiting order (a fingerprint of the
    /// weights, for comparing networks).
    pub fn flat_weights(&self) -> Vec<f32> {
        let mut c = Collect(Vec::new());
        self.visit(&mut c);
        c.0.into_iter().flat_map(|(_, v)| v).collect()
    }

    /// `(1 − w) · self + w · other`, element-wise, in a copy of `self` (its parameter ids
    /// kept, new storage): one step of an exponential moving average of `other`'s weights
    /// (`w = 1` copies them). Both must have the same parameters with the same shapes.
    ///
    /// # Errors
    /// Networks of different architectures, or `w` outside `[0, 1]`.
    pub fn blend_toward(&self, other: &QNet, w: f32) -> Result<QNet, String> {
        if !(0.0..=1.0).contains(&w) {
            return Err(format!("blend weight {w} outside [0, 1]"));
        }
        let collect = |net: &QNet| {
            let mut c = Collect(Vec::new());
            net.visit(&mut c);
            c.0
        };
        let (mine, theirs) = (collect(self), collect(other));
        if mine.len() != theirs.len() || mine.iter().zip(&theirs).any(|((a, _), (b, _))| a != b) {
            return Err("blending networks of different architectures".into());
        }
        let values: Vec<Vec<f32>> = mine
            .into_iter()
            .zip(theirs)
            .map(|((_, a), (_, b))| {
                a.iter().zip(&b).map(|(&a, &b)| a * (1.0 - w) + b * w).collect()
            })
            .collect();
        Ok(self.clone().map(&mut Replace(values.into_iter())))
    }

    /// The element-wise mean of the weights of `nets` (summed in `f64` in the order given),
    /// in a copy of the first. Each network must have the same parameters with the same
    /// shapes (the same variant and input): anything else is an error naming the first
    /// mismatch.
    ///
    /// # Errors
    /// No networks, or networks of different architectures.
    pub fn average(nets: &[&QNet]) -> Result<QNet, String> {
        let first = nets.first().ok_or("averaging needs at least one network")?;
        let collect = |net: &QNet| {
            let mut c = Collect(Vec::new());
            net.visit(&mut c);
            c.0
        };
        let base = collect(first);
        let mut sums: Vec<Vec<f64>> =
            base.iter().map(|(_, v)| v.iter().map(|&x| f64::from(x)).collect()).collect();
        for (k, net) in nets.iter().enumerate().skip(1) {
            let other = collect(net);
            if other.len() != base.len() {
                return Err(format!(
                    "network {} has {} parameter tensors, the first {}: not the same architecture",
                    k + 1,
                    other.len(),
                    base.len()
                ));
            }
            for (i, ((dims, values), sum)) in other.iter().zip(sums.iter_mut()).enumerate() {
                if *dims != base[i].0 {
                    return Err(format!(
                        "network {}: parameter {} is {dims:?}, the first network's {:?}: not the same architecture",
                        k + 1,
                        i + 1,
                        base[i].0
                    ));
                }
                for (s, &v) in sum.iter_mut().zip(values) {
                    *s += f64::from(v);
                }
            }
        }
        let n = nets.len() as f64;
        let means: Vec<Vec<f32>> =
            sums.into_iter().map(|s| s.into_iter().map(|v| (v / n) as f32).collect()).collect();
        Ok((*first).clone().map(&mut Replace(means.into_iter())))
    }
}

#[cfg(test)]
mod tests {
    use crate::{QNet, QNetConfig, Variant};

    fn weights(net: &QNet) -> Vec<f32> {
        net.flat_weights()
    }

    #[test]
    fn the_average_is_the_element_wise_mean() {
        let device = Default::default();
        let config = QNetConfig::new(Variant::LaserOnly);
        let nets: Vec<QNet> = (0..3).map(|s| config.init_seeded(&device, s)).collect();
        let avg = QNet::average(&nets.iter().collect::<Vec<_>>()).expect("same architecture");
        let (w, got) = (nets.iter().map(weights).collect::<Vec<_>>(), weights(&avg));
        assert_eq!(got.len(), w[0].len());
        for (i, g) in got.iter().enumerate() {
            let want =
                ((f64::from(w[0][i]) + f64::from(w[1][i]) + f64::from(w[2][i])) / 3.0) as f32;
            assert_eq!(*g, want, "weight {i}");
        }
        // One network averages to itself; the parameter ids are the first network's.
        let one = QNet::average(&[&nets[1]]).expect("one");
        assert_eq!(weights(&one), w[1]);
        // Different architectures are an error, not a silent mix.
        let other = QNetConfig::new(Variant::DepthOnly).init_seeded(&device, 0);
        let err = QNet::average(&[&nets[0], &other]).expect_err("different variants");
        assert!(err.contains("not the same architecture"), "{err}");
        assert!(QNet::average(&[]).is_err());
        // Blending: w = 1 copies, w = 0 keeps, between is (1 - w) a + w b; ids stay the first's.
        let (a, b) = (&nets[0], &nets[1]);
        assert_eq!(weights(&a.blend_toward(b, 1.0).expect("copy")), w[1]);
        assert_eq!(weights(&a.blend_toward(b, 0.0).expect("keep")), w[0]);
        let quarter = weights(&a.blend_toward(b, 0.25).expect("blend"));
        for (i, q) in quarter.iter().enumerate() {
            assert_eq!(*q, w[0][i] * 0.75 + w[1][i] * 0.25, "weight {i}");
        }
        assert!(a.blend_toward(&other, 0.5).is_err() && a.blend_toward(b, 1.5).is_err());
    }
}
