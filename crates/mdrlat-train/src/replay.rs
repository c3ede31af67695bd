//! Experience replay that stores each sensor frame once.
//!
//! A transition refers to its 4-frame stacks by frame ids; the frames live once in a ring of
//! `u16` millimetres (laser 1 KiB, depth 40 KiB per frame). Consecutive transitions of an
//! episode share three of their four frames, so 20,000 transitions cost ~0.84 GB instead of
//! the ~13 GB of two `f32` stacks each. When the frame ring wraps, transitions whose frames
//! are overwritten leave the buffer first (they are the oldest), so the buffer never returns
//! a stale frame.

use mdrlat_core::{
    DEPTH_LEN, FRAME_STACK, LASER_BEAMS, ODOM_HISTORY, Rng, normalize_depth, normalize_laser,
};
use std::collections::VecDeque;

/// A frame's id: frames are numbered in push order.
pub type FrameId = u64;

/// One stored transition `(s_t, a_t, r_t, s_{t+1})`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    /// Frames of `s_t`, oldest first.
    pub obs: [FrameId; FRAME_STACK],
    /// Frames of `s_{t+1}`, oldest first (for a truncated or terminated step: the true final
    /// observation).
    pub next: [FrameId; FRAME_STACK],
    /// Action index.
    pub action: u8,
    /// Reward.
    pub reward: f32,
    /// A collision ended the episode (only this zeroes the bootstrap; a time limit does not).
    pub terminated: bool,
    /// True `(v, ω)` at `t−2, t−1, t` of `s_t`: the auxiliary task's target.
    pub odom: [f32; 2 * ODOM_HISTORY],
}

impl Transition {
    fn oldest_frame(&self) -> FrameId {
        self.obs.iter().chain(&self.next).copied().min().unwrap_or(0)
    }
}

/// A sampled batch, normalised for the network (SPEC §2, `mdrlat_core::normalize_*`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Batch {
    /// Rows in the batch.
    pub size: usize,
    /// `[B, 4, 512]` laser of `s_t`.
    pub laser: Vec<f32>,
    /// `[B, 4, 128, 160]` depth of `s_t`.
    pub depth: Vec<f32>,
    /// `[B, 4, 512]` laser of `s_{t+1}`.
    pub next_laser: Vec<f32>,
    /// `[B, 4, 128, 160]` depth of `s_{t+1}`.
    pub next_depth: Vec<f32>,
    /// `[B]` action indices.
    pub actions: Vec<i64>,
    /// `[B]` rewards.
    pub rewards: Vec<f32>,
    /// `[B]` 1.0 where terminated.
    pub terminated: Vec<f32>,
    /// `[B, 6]` auxiliary targets.
    pub odom: Vec<f32>,
}

/// The replay buffer.
#[derive(Debug, Clone)]
pub struct ReplayBuffer {
    capacity: usize,
    frame_slots: usize,
    laser_mm: Vec<u16>,
    depth_mm: Vec<u16>,
    frames_pushed: u64,
    transitions: VecDeque<Transition>,
    /// Which sensors are stored (a laser-only run need not keep depth).
    keep_laser: bool,
    keep_depth: bool,
}

/// Metres to millimetres, rounded; 0 and negatives stay 0, beyond 65.535 m saturates.
fn to_mm(m: f32) -> u16 {
    if m.is_finite() && m > 0.0 { (m * 1000.0).round().min(u16::MAX as f32) as u16 } else { 0 }
}

fn to_m(mm: u16) -> f32 {
    mm as f32 / 1000.0
}

impl ReplayBuffer {
    /// A buffer of `capacity` transitions. `frame_reserve` extra frame slots absorb the
    /// extra first frame of every episode and the stacks in flight (a few hundred is ample).
    pub fn new(capacity: usize, frame_reserve: usize, keep_laser: bool, keep_depth: bool) -> Self {
        let frame_slots = capacity + frame_reserve.max(2 * FRAME_STACK);
        Self {
            capacity,
            frame_slots,
            laser_mm: if keep_laser { vec![0; frame_slots * LASER_BEAMS] } else { Vec::new() },
            depth_mm: if keep_depth { vec![0; frame_slots * DEPTH_LEN] } else { Vec::new() },
            frames_pushed: 0,
            transitions: VecDeque::with_capacity(capacity),
            keep_laser,
            keep_depth,
        }
    }

    /// Transitions held.
    pub fn len(&self) -> usize {
        self.transitions.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.transitions.is_empty()
    }

    /// Most transitions held.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Bytes of frame storage.
    pub fn memory_bytes(&self) -> usize {
        (self.laser_mm.len() + self.depth_mm.len()) * 2
            + self.transitions.capacity() * std::mem::size_of::<Transition>()
    }

    fn slot(&self, id: FrameId) -> usize {
        (id % self.frame_slots as u64) as usize
    }

    /// Stores one frame (metres) and returns its id. Transitions that referred to the frame
    /// it overwrites are dropped.
    pub fn push_frame(&mut self, laser_m: &[f32], depth_m: &[f32]) -> FrameId {
        let id = self.frames_pushed;
        self.frames_pushed += 1;
        if id >= self.frame_slots as u64 {
            let overwritten = id - self.frame_slots as u64;
            while self.transitions.front().is_some_and(|t| t.oldest_frame() <= overwritten) {
                self.transitions.pop_front();
            }
        }
        let s = self.slot(id);
        if self.keep_laser {
            for (o, &m) in
                self.laser_mm[s * LASER_BEAMS..(s + 1) * LASER_BEAMS].iter_mut().zip(laser_m)
            {
                *o = to_mm(m);
            }
        }
        if self.keep_depth {
            for (o, &m) in self.depth_mm[s * DEPTH_LEN..(s + 1) * DEPTH_LEN].iter_mut().zip(depth_m)
            {
                *o = to_mm(m);
            }
        }
        id
    }

    /// True if every frame of `t` is still stored.
    fn is_live(&self, t: &Transition) -> bool {
        let oldest_live = self.frames_pushed.saturating_sub(self.frame_slots as u64);
        t.oldest_frame() >= oldest_live
            && t.obs.iter().chain(&t.next).all(|&f| f < self.frames_pushed)
    }

    /// Stores a transition whose frames were pushed with [`ReplayBuffer::push_frame`]; the
    /// oldest transition leaves when full.
    ///
    /// # Panics
    /// If the transition refers to frames that are not stored (a programming error).
    pub fn push(&mut self, t: Transition) {
        assert!(self.is_live(&t), "transition refers to frames not in the buffer: {t:?}");
        if self.transitions.len() == self.capacity {
            self.transitions.pop_front();
        }
        self.transitions.push_back(t);
    }

    /// The `i`-th transition held, oldest first.
    pub fn get(&self, i: usize) -> Option<&Transition> {
        self.transitions.get(i)
    }

    /// Draws `batch` transition indices uniformly (with replacement, as DQN does).
    ///
    /// # Panics
    /// If the buffer is empty.
    pub fn sample_indices(&self, batch: usize, rng: &mut Rng) -> Vec<usize> {
        assert!(!self.is_empty(), "sampling an empty replay buffer");
        (0..batch).map(|_| rng.below(self.len())).collect()
    }

    /// Writes the stacks of frames `ids` (oldest first), normalised, into `laser` / `depth`.
    fn write_stack(
        &self,
        ids: &[FrameId; FRAME_STACK],
        laser: &mut [f32],
        depth: &mut [f32],
        scratch: &mut Vec<f32>,
    ) {
        for (k, &id) in ids.iter().enumerate() {
            let s = self.slot(id);
            if self.keep_laser {
                scratch.clear();
                scratch.extend(
                    self.laser_mm[s * LASER_BEAMS..(s + 1) * LASER_BEAMS]
                        .iter()
                        .map(|&mm| to_m(mm)),
                );
                normalize_laser(scratch, &mut laser[k * LASER_BEAMS..(k + 1) * LASER_BEAMS]);
            }
            if self.keep_depth {
                scratch.clear();
                scratch.extend(
                    self.depth_mm[s * DEPTH_LEN..(s + 1) * DEPTH_LEN].iter().map(|&mm| to_m(mm)),
                );
                normalize_depth(scratch, &mut depth[k * DEPTH_LEN..(k + 1) * DEPTH_LEN]);
            }
        }
    }

    /// Fills `out` with the transitions at `indices`, normalised for the network. Buffers
    /// in `out` are reused.
    pub fn write_batch(&self, indices: &[usize], out: &mut Batch) {
        let b = indices.len();
        let (ls, ds) = (FRAME_STACK * LASER_BEAMS, FRAME_STACK * DEPTH_LEN);
        let lasers = if self.keep_laser { b * ls } else { 0 };
        let depths = if self.keep_depth { b * ds } else { 0 };
        out.size = b;
        for (v, n) in [
            (&mut out.laser, lasers),
            (&mut out.next_laser, lasers),
            (&mut out.depth, depths),
            (&mut out.next_depth, depths),
        ] {
            v.resize(n, 0.0);
        }
        out.actions.clear();
        out.rewards.clear();
        out.terminated.clear();
        out.odom.clear();
        let mut scratch = Vec::with_capacity(DEPTH_LEN);
        for (row, &i) in indices.iter().enumerate() {
            let t = &self.transitions[i];
            let (lr, dr) = (
                if self.keep_laser { row * ls..(row + 1) * ls } else { 0..0 },
                if self.keep_depth { row * ds..(row + 1) * ds } else { 0..0 },
            );
            self.write_stack(
                &t.obs,
                &mut out.laser[lr.clone()],
                &mut out.depth[dr.clone()],
                &mut scratch,
            );
            self.write_stack(
                &t.next,
                &mut out.next_laser[lr],
                &mut out.next_depth[dr],
                &mut scratch,
            );
            out.actions.push(i64::from(t.action));
            out.rewards.push(t.reward);
            out.terminated.push(if t.terminated { 1.0 } else { 0.0 });
            out.odom.extend_from_slice(&t.odom);
        }
    }
}
