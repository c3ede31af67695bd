//! Prioritised experience replay, proportional variant (Schaul et al., *Prioritized
//! Experience Replay*, ICLR 2016): transition `i` is drawn with probability
//! `P(i) = p_i / Σ_k p_k`, `p_i = (|δ_i| + ε)^α` from its last TD error `δ_i`; a new
//! transition gets the largest priority so far, so that it is replayed at least once. The
//! bias this puts into the TD loss's expectation is corrected by importance-sampling
//! weights `w_i = (N · P(i))^−β`, divided by the batch's largest, with `β` annealed to 1 by
//! the end of the run (`train.priority_beta`).
//!
//! Priorities live in a sum tree over the replay's capacity: a sample and an update are
//! `O(log N)`. A transition keeps its leaf (its sequence number modulo the capacity) while it
//! is held, so every sum in the tree is a function of the leaves alone, always recomputed from
//! the two children: a tree rebuilt from a checkpoint's leaves is the same bits, and a
//! resumed run draws the same batches as one that never stopped.

use mdrlat_core::Rng;
use serde::{Deserialize, Serialize};

/// A binary tree of sums over `capacity` non-negative leaves.
#[derive(Debug, Clone, PartialEq)]
struct SumTree {
    /// Leaves, a power of two ≥ the capacity (the rest stay 0).
    leaves: usize,
    /// `nodes[1]` is the root, `nodes[leaves + i]` leaf `i`; `nodes[0]` is unused.
    nodes: Vec<f64>,
}

impl SumTree {
    fn new(capacity: usize) -> Self {
        let leaves = capacity.max(1).next_power_of_two();
        Self { leaves, nodes: vec![0.0; 2 * leaves] }
    }

    fn total(&self) -> f64 {
        self.nodes[1]
    }

    fn get(&self, leaf: usize) -> f64 {
        self.nodes[self.leaves + leaf]
    }

    /// Sets leaf `leaf` and recomputes its ancestors from their children.
    fn set(&mut self, leaf: usize, value: f64) {
        let mut i = self.leaves + leaf;
        self.nodes[i] = value;
        while i > 1 {
            i /= 2;
            self.nodes[i] = self.nodes[2 * i] + self.nodes[2 * i + 1];
        }
    }

    /// The leaf where the running sum of the leaves passes `u` (`0 ≤ u < total`). Only a
    /// leaf with a positive value is returned while the total is positive (a rounding
    /// overshoot at a node with an empty right side stays on the left).
    fn find(&self, mut u: f64) -> usize {
        let mut i = 1;
        while i < self.leaves {
            let (left, right) = (self.nodes[2 * i], self.nodes[2 * i + 1]);
            if u < left || right <= 0.0 {
                i *= 2;
            } else {
                u -= left;
                i = 2 * i + 1;
            }
        }
        i - self.leaves
    }
}

/// The priorities of a replay buffer's transitions (see the module's documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct Priorities {
    alpha: f32,
    epsilon: f32,
    capacity: usize,
    tree: SumTree,
    /// The largest priority given so far (a new transition's).
    max: f64,
    /// Transitions that have left the front of the buffer since it was created, modulo the
    /// capacity: the transition at index `i` (oldest first) has leaf
    /// `(removed + i) % capacity`.
    removed: u64,
}

/// What a checkpoint keeps of [`Priorities`]: enough to rebuild the same tree. The
/// priorities are kept as the bits of their `f64` (`f64::to_bits`): a decimal text read
/// back may differ in the last bit, and a resumed run must draw what the run would have.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PriorityState {
    /// Transitions removed from the front so far, modulo the capacity (fixes each one's
    /// leaf).
    pub removed: u64,
    /// The bits of the largest priority so far.
    pub max_bits: u64,
    /// The bits of each held transition's priority `p_i`, oldest first.
    pub value_bits: Vec<u64>,
}

impl Priorities {
    /// Priorities for a buffer of `capacity` transitions: exponent `alpha` (0 < α ≤ 1) and
    /// offset `epsilon` > 0 of `p = (|δ| + ε)^α`.
    pub fn new(capacity: usize, alpha: f32, epsilon: f32) -> Self {
        Self { alpha, epsilon, capacity, tree: SumTree::new(capacity), max: 1.0, removed: 0 }
    }

    fn leaf(&self, index: usize) -> usize {
        ((self.removed + index as u64) % self.capacity as u64) as usize
    }

    /// The transition that was at index 0 left the buffer.
    pub(crate) fn remove_front(&mut self) {
        let leaf = self.leaf(0);
        self.tree.set(leaf, 0.0);
        self.removed = (self.removed + 1) % self.capacity as u64;
    }

    /// A transition was stored at `index` (the buffer's length before it): it gets the
    /// largest priority so far.
    pub(crate) fn push(&mut self, index: usize) {
        let leaf = self.leaf(index);
        self.tree.set(leaf, self.max);
    }

    /// Priority `p_i` of the transition at `index`.
    pub fn get(&self, index: usize) -> f64 {
        self.tree.get(self.leaf(index))
    }

    /// Sum of the held transitions' priorities.
    pub fn total(&self) -> f64 {
        self.tree.total()
    }

    /// Draws `batch` indices of a buffer holding `len` transitions, one from each of
    /// `batch` equal slices of the total priority (stratified, as Schaul et al.), with
    /// their importance-sampling weights `(len · P(i))^−β / max_batch`. One uniform draw of
    /// `rng` per row.
    pub(crate) fn sample(
        &self,
        len: usize,
        batch: usize,
        beta: f32,
        rng: &mut Rng,
    ) -> (Vec<usize>, Vec<f32>) {
        let total = self.tree.total();
        let slice = total / batch as f64;
        let first = self.removed as usize;
        let mut indices = Vec::with_capacity(batch);
        let mut weights = Vec::with_capacity(batch);
        for j in 0..batch {
            let u = ((j as f64 + rng.uniform()) * slice).min(total * (1.0 - f64::EPSILON));
            let leaf = self.tree.find(u);
            indices.push((leaf + self.capacity - first) % self.capacity);
            let p = self.tree.get(leaf) / total;
            weights.push((len as f64 * p).powf(-f64::from(beta)));
        }
        let largest = weights.iter().copied().fold(0.0f64, f64::max);
        let weights = weights.iter().map(|w| (w / largest) as f32).collect();
        (indices, weights)
    }

    /// New priorities from the TD errors `td[k]` of the transitions at `indices[k]` (a
    /// transition drawn twice takes its last error). A non-finite error gets the largest
    /// priority so far rather than poisoning the tree.
    pub(crate) fn update(&mut self, indices: &[usize], td: &[f32]) {
        for (&i, &d) in indices.iter().zip(td) {
            let p = if d.is_finite() {
                f64::from(d.abs() + self.epsilon).powf(f64::from(self.alpha))
            } else {
                self.max
            };
            self.max = self.max.max(p);
            let leaf = self.leaf(i);
            self.tree.set(leaf, p);
        }
    }

    /// The state a checkpoint keeps, for a buffer holding `len` transitions.
    pub fn state(&self, len: usize) -> PriorityState {
        PriorityState {
            removed: self.removed,
            max_bits: self.max.to_bits(),
            value_bits: (0..len).map(|i| self.get(i).to_bits()).collect(),
        }
    }

    /// Priorities rebuilt from a checkpoint's `state` for a buffer holding `len`
    /// transitions.
    ///
    /// # Errors
    /// A state of another length, a `removed` count beyond the capacity, or a priority that
    /// is not positive, not finite or above the largest.
    pub fn restore(
        capacity: usize,
        alpha: f32,
        epsilon: f32,
        state: &PriorityState,
        len: usize,
    ) -> Result<Self, String> {
        if state.value_bits.len() != len {
            return Err(format!(
                "{} priorities for {len} replayed transitions",
                state.value_bits.len()
            ));
        }
        if state.removed >= capacity.max(1) as u64 {
            return Err(format!(
                "removed count {} is not below the capacity {capacity}",
                state.removed
            ));
        }
        let max = f64::from_bits(state.max_bits);
        if !(max.is_finite() && max > 0.0) {
            return Err(format!("bad largest priority {max}"));
        }
        let mut p = Self::new(capacity, alpha, epsilon);
        (p.removed, p.max) = (state.removed, max);
        for (i, v) in state.value_bits.iter().map(|&b| f64::from_bits(b)).enumerate() {
            if !(v.is_finite() && v > 0.0 && v <= max) {
                return Err(format!("bad priority {v} of transition {i}"));
            }
            let leaf = p.leaf(i);
            p.tree.set(leaf, v);
        }
        Ok(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tree_finds_leaves_in_proportion_and_never_an_empty_one() {
        let mut t = SumTree::new(5);
        for (i, v) in [1.0, 0.0, 3.0, 0.0, 4.0].into_iter().enumerate() {
            t.set(i, v);
        }
        assert_eq!(t.total(), 8.0);
        assert_eq!(t.find(0.0), 0);
        assert_eq!(t.find(0.999), 0);
        assert_eq!(t.find(1.0), 2);
        assert_eq!(t.find(3.999), 2);
        assert_eq!(t.find(4.0), 4);
        // A rounding overshoot past the total stays on a positive leaf.
        assert_eq!(t.find(8.5), 4);
        t.set(4, 0.0);
        assert_eq!(t.find(4.5), 2);
    }

    #[test]
    fn sampling_follows_the_priorities_and_weights_undo_them() {
        let mut p = Priorities::new(4, 1.0, 0.0);
        for i in 0..4 {
            p.push(i);
        }
        // Priorities 1, 1, 1, 5 (α = 1, ε = 0): the last is drawn 5/8 of the time.
        p.update(&[3], &[5.0]);
        let mut rng = Rng::seed_from_u64(7);
        let mut counts = [0usize; 4];
        for _ in 0..2000 {
            let (idx, w) = p.sample(4, 8, 0.5, &mut rng);
            for (&i, &wi) in idx.iter().zip(&w) {
                counts[i] += 1;
                // (4 · P)^−½, over the batch's largest (a priority-1 row, P = 1/8).
                let expect = if i == 3 { (2.5f64 / 0.5).powf(-0.5) as f32 } else { 1.0 };
                assert!((wi - expect).abs() < 1e-6 || !idx.iter().any(|&k| k != 3), "{wi}");
            }
        }
        let share = counts[3] as f64 / 16000.0;
        assert!((share - 0.625).abs() < 0.02, "{counts:?}");
        for c in &counts[..3] {
            assert!((*c as f64 / 16000.0 - 0.125).abs() < 0.02, "{counts:?}");
        }
    }

    #[test]
    fn new_transitions_get_the_largest_priority_and_leaving_ones_none() {
        let mut p = Priorities::new(3, 0.5, 0.01);
        for i in 0..3 {
            p.push(i);
        }
        p.update(&[0, 1], &[15.99, 0.0]);
        let big = (16.0f64).sqrt();
        assert!((p.max - big).abs() < 1e-6);
        // Full: the oldest leaves, the newcomer takes its leaf with the largest priority.
        p.remove_front();
        p.push(2);
        assert!((p.get(2) - big).abs() < 1e-6);
        assert!((p.get(0) - f64::from(0.01f32).sqrt()).abs() < 1e-6);
        assert!((p.total() - (p.get(0) + p.get(1) + p.get(2))).abs() < 1e-12);
    }

    #[test]
    fn a_restored_state_is_the_same_tree_and_bad_states_are_refused() {
        let mut p = Priorities::new(5, 0.6, 0.001);
        let mut rng = Rng::seed_from_u64(3);
        for i in 0..5 {
            p.push(i);
        }
        for step in 0..40 {
            p.remove_front();
            p.push(4);
            let (idx, _) = p.sample(5, 3, 0.4, &mut rng);
            let td: Vec<f32> = idx.iter().map(|&i| (i * 7 + step) as f32 % 3.3).collect();
            p.update(&idx, &td);
        }
        let state = p.state(5);
        // Through the checkpoint's JSON: the same bits (decimals might lose the last one).
        let text = serde_json::to_string(&state).expect("json");
        let state: PriorityState = serde_json::from_str(&text).expect("json");
        let back = Priorities::restore(5, 0.6, 0.001, &state, 5).expect("restore");
        assert_eq!(back, p);
        assert!((0..5).any(|i| p.get(i) != p.max), "learned priorities, not only new ones");
        assert!(Priorities::restore(5, 0.6, 0.001, &state, 4).is_err());
        let mut bad = state.clone();
        bad.value_bits[2] = f64::NAN.to_bits();
        let e = Priorities::restore(5, 0.6, 0.001, &bad, 5).expect_err("a NaN priority");
        assert!(e.contains("transition 2"), "{e}");
        let mut bad = state.clone();
        bad.value_bits[0] = (f64::from_bits(bad.max_bits) * 2.0).to_bits();
        assert!(Priorities::restore(5, 0.6, 0.001, &bad, 5).is_err());
        let mut bad = state;
        bad.removed = u64::MAX;
        let e = Priorities::restore(5, 0.6, 0.001, &bad, 5).expect_err("a corrupt count");
        assert!(e.contains("removed"), "{e}");
    }
}
