//! Experience replay that stores each sensor frame once.
//!
//! A transition refers to its 4-frame stacks by frame ids; the frames live once in a ring of
//! `u16` millimetres (laser 1 KiB, depth 40 KiB per frame). Consecutive transitions of an
//! episode share three of their four frames, so 20,000 transitions cost ~0.94 GB instead of
//! the ~13 GB of two `f32` stacks each. When the frame ring wraps, transitions whose frames
//! are overwritten leave the buffer first (they are the oldest), so the buffer never returns
//! a stale frame. The navigation task's goal (three numbers in the robot frame) is stored
//! with each transition, for `s_t` and `s_{t+1}`.

use crate::priority::Priorities;
use mdrlat_core::{
    DEPTH_LEN, FRAME_STACK, GOAL_DIM, LASER_BEAMS, ODOM_HISTORY, Rng, normalize_depth,
    normalize_goal, normalize_laser,
};
use rayon::prelude::*;
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
    /// Reward: with `steps` > 1 the discounted sum `Σ γ^i r_{t+i}` of those steps' rewards.
    pub reward: f32,
    /// A collision, or in navigation the arrival at the goal, ended the episode (only this
    /// zeroes the bootstrap; a time limit does not).
    pub terminated: bool,
    /// Environment steps from `s_t` to the stored `s'` (`train.n_step`; 1 in the paper, fewer
    /// than `n_step` at an episode's end): the bootstrap is discounted by `γ^steps`.
    pub steps: u8,
    /// True `(v, ω)` at `t−2, t−1, t` of `s_t`: the auxiliary task's target.
    pub odom: [f32; 2 * ODOM_HISTORY],
    /// The goal of `s_t` in the robot frame (`mdrlat_core::goal_in_robot_frame`, metres;
    /// zeros in obstacle avoidance, where the buffer does not store it).
    pub goal: [f32; GOAL_DIM],
    /// The goal of `s_{t+1}`.
    pub next_goal: [f32; GOAL_DIM],
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
    /// `[B]` environment steps from `s` to `s'` (see [`Transition::steps`]).
    pub steps: Vec<u8>,
    /// `[B, 6]` auxiliary targets.
    pub odom: Vec<f32>,
    /// `[B, 3]` normalised goal of `s_t` (`mdrlat_core::normalize_goal`; empty without goals).
    pub goal: Vec<f32>,
    /// `[B, 3]` normalised goal of `s_{t+1}`.
    pub next_goal: Vec<f32>,
    /// The depth frames as stored, for a device that builds the stacks itself
    /// ([`DepthLayout::Frames`]; `depth` and `next_depth` are then empty). Empty otherwise.
    pub depth_frames: DepthFrames,
    /// `[B]` importance-sampling weights of the TD loss, with prioritised replay
    /// ([`ReplayBuffer::sample_weighted`]); empty: every row weighs 1.
    pub weights: Vec<f32>,
}

/// How a sampled batch carries its depth input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DepthLayout {
    /// Normalised `f32` stacks, `[B, 4, 128, 160]` for `s` and for `s'` (`Batch::depth`,
    /// `Batch::next_depth`).
    #[default]
    Stacks,
    /// Each distinct frame of the batch once, in stored millimetres, and for each stack which
    /// frames it holds (`Batch::depth_frames`): ~5 frames a row instead of 8, and 2 bytes a
    /// value instead of 4. A GPU reads a third of the bytes and builds the stacks itself with
    /// [`depth_table`], into the same values. (A learner on `flex` given such a batch convolves
    /// those stacks directly, not through the patches it cuts from a batch of stacks: the
    /// same values, other last bits; `Learner::depth_layout` never asks for it there.)
    Frames,
}

/// A batch's depth frames in [`DepthLayout::Frames`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DepthFrames {
    /// `[F, 128 × 160]`: the distinct frames of the batch, in millimetres as stored.
    pub mm: Vec<u16>,
    /// `[B, 4]`: the row of `mm` that is frame `k` (oldest first) of row `i`'s `s`.
    pub obs: Vec<i64>,
    /// `[B, 4]`: the same for `s'`.
    pub next: Vec<i64>,
}

impl DepthFrames {
    /// Distinct frames held.
    pub fn len(&self) -> usize {
        self.mm.len() / DEPTH_LEN
    }

    /// True when it holds no frame (a batch in [`DepthLayout::Stacks`]).
    pub fn is_empty(&self) -> bool {
        self.mm.is_empty()
    }

    fn clear(&mut self) {
        self.mm.clear();
        self.obs.clear();
        self.next.clear();
    }
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
    /// Whether goals are stored (the navigation task).
    keep_goal: bool,
    /// How many frames before an overwritten one a transition at the front may still hold
    /// (see [`ReplayBuffer::with_envs`]).
    frame_margin: u64,
    /// The transitions' priorities, with prioritised replay (`train.priority_alpha` > 0).
    priorities: Option<Priorities>,
}

/// Metres to millimetres, rounded; 0 and negatives stay 0, beyond 65.535 m saturates.
fn to_mm(m: f32) -> u16 {
    if m.is_finite() && m > 0.0 { (m * 1000.0).round().min(u16::MAX as f32) as u16 } else { 0 }
}

fn to_m(mm: u16) -> f32 {
    mm as f32 / 1000.0
}

/// The network input of every stored value, `normalize(to_m(mm))`, for one sensor: a
/// sampled batch reads 5 M depth values a step, and the two divisions a value took (metres,
/// then the normalisation) cost more than a lookup in this 256 KB table, which gives the
/// same bits.
struct NormTable(Box<[f32; 1 << 16]>);

impl NormTable {
    fn new(normalize: fn(&[f32], &mut [f32])) -> Self {
        let metres: Vec<f32> = (0..=u16::MAX).map(to_m).collect();
        let mut table = Box::new([0.0; 1 << 16]);
        normalize(&metres, &mut table[..]);
        Self(table)
    }

    /// `out[i] = normalize(to_m(mm[i]))`.
    fn write(&self, mm: &[u16], out: &mut [f32]) {
        debug_assert_eq!(mm.len(), out.len());
        for (o, &v) in out.iter_mut().zip(mm) {
            *o = self.0[usize::from(v)];
        }
    }
}

/// The two sensors' tables, built on first use.
fn norm_tables() -> &'static (NormTable, NormTable) {
    static TABLES: std::sync::OnceLock<(NormTable, NormTable)> = std::sync::OnceLock::new();
    TABLES.get_or_init(|| (NormTable::new(normalize_laser), NormTable::new(normalize_depth)))
}

/// The network input of every stored depth value: entry `mm` is what a depth stack holds
/// for a pixel stored as `mm` millimetres (see [`DepthLayout::Frames`]).
pub fn depth_table() -> &'static [f32; 1 << 16] {
    &norm_tables().1.0
}

impl ReplayBuffer {
    /// A buffer of `capacity` transitions. `frame_reserve` extra frame slots absorb the
    /// extra first frame of every episode: with episodes of L steps the buffer holds
    /// `min(capacity, (capacity + reserve) · L / (L + 1))` transitions (see
    /// `checkpoint::frame_reserve`).
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
            keep_goal: false,
            frame_margin: 0,
            priorities: None,
        }
    }

    /// The same buffer drawing transitions in proportion to their priorities
    /// (`p = (|δ| + epsilon)^alpha`, [`crate::priority`]), or uniformly with `None`.
    pub fn with_priorities(mut self, priorities: Option<Priorities>) -> Self {
        self.priorities = priorities;
        self
    }

    /// The priorities, with prioritised replay.
    pub fn priorities(&self) -> Option<&Priorities> {
        self.priorities.as_ref()
    }

    /// Draws `batch` transition indices in proportion to their priorities, with their
    /// importance-sampling weights at exponent `beta` ([`Priorities`]); uniformly with
    /// replacement and no weights (empty) without prioritised replay, as
    /// [`ReplayBuffer::sample_indices`].
    ///
    /// # Panics
    /// If the buffer is empty.
    pub fn sample_weighted(
        &self,
        batch: usize,
        beta: f32,
        rng: &mut Rng,
    ) -> (Vec<usize>, Vec<f32>) {
        match &self.priorities {
            Some(p) => {
                assert!(!self.is_empty(), "sampling an empty replay buffer");
                p.sample(self.len(), batch, beta, rng)
            }
            None => (self.sample_indices(batch, rng), Vec::new()),
        }
    }

    /// New priorities from the TD errors of the transitions at `indices` (a batch just
    /// drawn by [`ReplayBuffer::sample_weighted`], before anything was stored); nothing
    /// without prioritised replay.
    pub fn update_priorities(&mut self, indices: &[usize], td_errors: &[f32]) {
        if let Some(p) = &mut self.priorities {
            p.update(indices, td_errors);
        }
    }

    /// Drops the oldest transition (and its priority).
    fn pop_front(&mut self) {
        if self.transitions.pop_front().is_some()
            && let Some(p) = &mut self.priorities
        {
            p.remove_front();
        }
    }

    /// The same buffer filled by `envs` environments in turn. One environment's transitions
    /// arrive with their oldest frames in order, so dropping transitions from the front
    /// until the front's frames are live drops every transition with an overwritten frame.
    /// Interleaved, a later transition's oldest frame may precede the front's by up to four
    /// of its environment's steps (`3 + n_step` with n-step returns, whose `s` is `n_step`
    /// steps old when stored) — at most two frames each (a step's and a reset's) from every
    /// environment: the front goes while its oldest frame is within that margin of the
    /// overwritten one, so no held transition refers to a lost frame.
    pub fn with_envs(mut self, envs: usize, n_step: usize) -> Self {
        let ticks = FRAME_STACK + n_step.max(1) - 1;
        self.frame_margin = if envs > 1 { (2 * ticks * envs) as u64 } else { 0 };
        self
    }

    /// The same buffer storing each transition's goals (the navigation task) or not.
    pub fn with_goals(mut self, keep: bool) -> Self {
        self.keep_goal = keep;
        self
    }

    /// Whether it stores goals.
    pub fn keeps_goals(&self) -> bool {
        self.keep_goal
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
            let reach = overwritten + self.frame_margin;
            while self.transitions.front().is_some_and(|t| t.oldest_frame() <= reach) {
                self.pop_front();
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

    /// True if frame `id` is still stored.
    pub fn holds_frame(&self, id: FrameId) -> bool {
        id < self.frames_pushed && id >= self.frames_pushed.saturating_sub(self.frame_slots as u64)
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
            self.pop_front();
        }
        if let Some(p) = &mut self.priorities {
            p.push(self.transitions.len());
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

    /// Writes the stacks of frames `ids` (oldest first), normalised, into `laser` / `depth`
    /// (a sensor whose slice is empty is not written: not kept, or sent as frames).
    /// Frames also in `written` — `(ids, laser, depth)` of a stack already written, e.g. `s`
    /// when writing `s'`, which shares its three older frames — are copied from there
    /// instead of converted again (the same values: one stored frame).
    fn write_stack(
        &self,
        ids: &[FrameId; FRAME_STACK],
        (laser, depth): (&mut [f32], &mut [f32]),
        written: Option<(&[FrameId; FRAME_STACK], &[f32], &[f32])>,
    ) {
        let (laser_table, depth_table) = norm_tables();
        let (keep_laser, keep_depth) = (!laser.is_empty(), !depth.is_empty());
        for (k, &id) in ids.iter().enumerate() {
            // Frame k's values (indexed only for a sensor the buffer keeps).
            let (l, d) =
                (k * LASER_BEAMS..(k + 1) * LASER_BEAMS, k * DEPTH_LEN..(k + 1) * DEPTH_LEN);
            if let Some((done, done_l, done_d)) = written
                && let Some(j) = done.iter().position(|&other| other == id)
            {
                if keep_laser {
                    laser[l].copy_from_slice(&done_l[j * LASER_BEAMS..(j + 1) * LASER_BEAMS]);
                }
                if keep_depth {
                    depth[d].copy_from_slice(&done_d[j * DEPTH_LEN..(j + 1) * DEPTH_LEN]);
                }
                continue;
            }
            let s = self.slot(id);
            if keep_laser {
                laser_table
                    .write(&self.laser_mm[s * LASER_BEAMS..(s + 1) * LASER_BEAMS], &mut laser[l]);
            }
            if keep_depth {
                depth_table
                    .write(&self.depth_mm[s * DEPTH_LEN..(s + 1) * DEPTH_LEN], &mut depth[d]);
            }
        }
    }

    /// Fills `out` with the transitions at `indices`, normalised for the network. Buffers
    /// in `out` are reused.
    pub fn write_batch(&self, indices: &[usize], out: &mut Batch) {
        self.write_batch_as(indices, out, DepthLayout::Stacks);
    }

    /// [`ReplayBuffer::write_batch`] with the depth input in `layout`.
    pub fn write_batch_as(&self, indices: &[usize], out: &mut Batch, layout: DepthLayout) {
        let b = indices.len();
        let frames = layout == DepthLayout::Frames && self.keep_depth;
        // Values a row of each sensor's stack (0 for a sensor the buffer does not keep, or
        // whose frames go as they are).
        let ls = if self.keep_laser { FRAME_STACK * LASER_BEAMS } else { 0 };
        let ds = if self.keep_depth && !frames { FRAME_STACK * DEPTH_LEN } else { 0 };
        out.depth_frames.clear();
        if frames {
            self.write_depth_frames(indices, &mut out.depth_frames);
        }
        out.size = b;
        for (v, n) in [
            (&mut out.laser, ls),
            (&mut out.next_laser, ls),
            (&mut out.depth, ds),
            (&mut out.next_depth, ds),
        ] {
            v.resize(b * n, 0.0);
        }
        out.actions.clear();
        out.rewards.clear();
        out.terminated.clear();
        out.steps.clear();
        out.odom.clear();
        out.goal.clear();
        out.next_goal.clear();
        // The stacks, a row per task on the pool's threads (each row is its own; the
        // conversion and normalisation of 8 frames a row are most of a batch's sampling).
        let (l, nl) = (rows(&mut out.laser, ls, b), rows(&mut out.next_laser, ls, b));
        let (d, nd) = (rows(&mut out.depth, ds, b), rows(&mut out.next_depth, ds, b));
        l.into_par_iter().zip(nl).zip(d).zip(nd).zip(indices).for_each(
            |((((l, nl), d), nd), &i)| {
                let t = &self.transitions[i];
                self.write_stack(&t.obs, (&mut *l, &mut *d), None);
                self.write_stack(&t.next, (nl, nd), Some((&t.obs, l, d)));
            },
        );
        for &i in indices {
            let t = &self.transitions[i];
            out.actions.push(i64::from(t.action));
            out.rewards.push(t.reward);
            out.terminated.push(if t.terminated { 1.0 } else { 0.0 });
            out.steps.push(t.steps);
            out.odom.extend_from_slice(&t.odom);
            if self.keep_goal {
                out.goal.extend_from_slice(&normalize_goal(&t.goal));
                out.next_goal.extend_from_slice(&normalize_goal(&t.next_goal));
            }
        }
    }
}

impl ReplayBuffer {
    /// The depth frames of the transitions at `indices` in [`DepthLayout::Frames`]: each
    /// distinct frame once, in order of first use (`s` before `s'`, row by row).
    fn write_depth_frames(&self, indices: &[usize], out: &mut DepthFrames) {
        let mut ids: Vec<FrameId> = Vec::with_capacity(indices.len() * 2 * FRAME_STACK);
        let mut row_of = std::collections::HashMap::with_capacity(ids.capacity());
        for &i in indices {
            let t = &self.transitions[i];
            for (stack, &id) in std::iter::repeat_n(false, FRAME_STACK)
                .chain(std::iter::repeat_n(true, FRAME_STACK))
                .zip(t.obs.iter().chain(&t.next))
            {
                let row = *row_of.entry(id).or_insert_with(|| {
                    ids.push(id);
                    ids.len() as i64 - 1
                });
                if stack { out.next.push(row) } else { out.obs.push(row) }
            }
        }
        out.mm.resize(ids.len() * DEPTH_LEN, 0);
        out.mm.par_chunks_mut(DEPTH_LEN).zip(&ids).for_each(|(frame, &id)| {
            let s = self.slot(id);
            frame.copy_from_slice(&self.depth_mm[s * DEPTH_LEN..(s + 1) * DEPTH_LEN]);
        });
    }
}

/// `v` as `batch` rows of `len` values (`batch` empty rows when `len` is 0: a sensor the
/// variant does not keep).
fn rows(v: &mut [f32], len: usize, batch: usize) -> Vec<&mut [f32]> {
    debug_assert_eq!(v.len(), len * batch, "rows: {} values for {batch} x {len}", v.len());
    if len == 0 {
        return (0..batch).map(|_| Default::default()).collect();
    }
    v.chunks_mut(len).collect()
}

/// Magic and version of the replay file format.
const REPLAY_MAGIC: &[u8; 8] = b"MDRLRB01";
/// The same format with goals: a third flag byte and the two goals after each record's
/// targets. Obstacle-avoidance buffers keep writing the first, byte for byte as before.
const REPLAY_MAGIC_GOALS: &[u8; 8] = b"MDRLRB02";

/// Bytes of one transition record.
fn record_len(goals: bool) -> usize {
    8 * 2 * FRAME_STACK + 1 + 4 + 1 + 4 * 2 * ODOM_HISTORY + usize::from(goals) * 4 * 2 * GOAL_DIM
}

fn io_err(msg: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidData, msg)
}

impl ReplayBuffer {
    /// Writes the whole buffer (frames and transitions) in mdrlat's replay format
    /// (little-endian; see `read_from`).
    ///
    /// # Errors
    /// Any write error.
    pub fn write_to(&self, mut w: impl std::io::Write) -> std::io::Result<()> {
        w.write_all(if self.keep_goal { REPLAY_MAGIC_GOALS } else { REPLAY_MAGIC })?;
        for v in [
            self.capacity as u64,
            self.frame_slots as u64,
            self.frames_pushed,
            self.transitions.len() as u64,
        ] {
            w.write_all(&v.to_le_bytes())?;
        }
        w.write_all(&[u8::from(self.keep_laser), u8::from(self.keep_depth)])?;
        if self.keep_goal {
            w.write_all(&[1])?;
        }
        let mut bytes = Vec::with_capacity(1 << 20);
        for chunk in [&self.laser_mm, &self.depth_mm] {
            for part in chunk.chunks(1 << 19) {
                bytes.clear();
                bytes.extend(part.iter().flat_map(|v| v.to_le_bytes()));
                w.write_all(&bytes)?;
            }
        }
        for t in &self.transitions {
            bytes.clear();
            for id in t.obs.iter().chain(&t.next) {
                bytes.extend_from_slice(&id.to_le_bytes());
            }
            bytes.push(t.action);
            bytes.extend_from_slice(&t.reward.to_le_bytes());
            // Bit 0: terminated; bits 1–7: steps − 1 (0 for one step: the byte of files
            // written before n-step returns).
            bytes.push(u8::from(t.terminated) | (t.steps.saturating_sub(1) << 1));
            for o in t.odom {
                bytes.extend_from_slice(&o.to_le_bytes());
            }
            if self.keep_goal {
                for g in t.goal.iter().chain(&t.next_goal) {
                    bytes.extend_from_slice(&g.to_le_bytes());
                }
            }
            w.write_all(&bytes)?;
        }
        Ok(())
    }

    /// Reads a buffer written by [`ReplayBuffer::write_to`]; it must have the given capacity
    /// and sensors, and store goals exactly when `keep_goal`; `envs` environments filled it
    /// with `n_step` returns (see [`ReplayBuffer::with_envs`]).
    ///
    /// # Errors
    /// A read error, a truncated or foreign file, or a buffer of another shape.
    #[allow(clippy::too_many_arguments)]
    pub fn read_from(
        mut r: impl std::io::Read,
        len: u64,
        capacity: usize,
        frame_reserve: usize,
        keep_laser: bool,
        keep_depth: bool,
        keep_goal: bool,
        (envs, n_step): (usize, usize),
    ) -> std::io::Result<Self> {
        let mut magic = [0u8; 8];
        r.read_exact(&mut magic)?;
        let goals = match &magic {
            m if m == REPLAY_MAGIC => false,
            m if m == REPLAY_MAGIC_GOALS => true,
            _ => return Err(io_err("not an mdrlat replay file (bad magic)".into())),
        };
        let mut u64s = [0u64; 4];
        for v in &mut u64s {
            let mut b = [0u8; 8];
            r.read_exact(&mut b)?;
            *v = u64::from_le_bytes(b);
        }
        let [cap, slots, pushed, count] = u64s;
        let mut flags = [0u8; 3];
        r.read_exact(&mut flags[..2 + usize::from(goals)])?;
        if goals && flags[2] != 1 {
            return Err(io_err(format!("bad goal flag {} in the replay header", flags[2])));
        }
        if cap != capacity as u64 || flags[..2] != [u8::from(keep_laser), u8::from(keep_depth)] {
            return Err(io_err(format!(
                "replay holds capacity {cap} with sensors {:?}, the run needs {capacity} with {:?}",
                &flags[..2],
                [u8::from(keep_laser), u8::from(keep_depth)]
            )));
        }
        if goals != keep_goal {
            let holds = |g: bool| if g { "with goals (navigation)" } else { "without goals" };
            return Err(io_err(format!(
                "replay holds transitions {}, the run needs them {}",
                holds(goals),
                holds(keep_goal)
            )));
        }
        // The file's own frame reserve is kept (older builds used a smaller one); it must be
        // sane, and the length check below comes before any allocation it implies.
        let reserve_ok = slots >= cap + 2 * FRAME_STACK as u64
            && slots <= cap + (frame_reserve as u64).max(cap) + 1024;
        if !reserve_ok || count > cap || pushed < count || pushed > 1 << 62 {
            return Err(io_err(format!(
                "inconsistent replay header: {slots} slots, {count} transitions, {pushed} frames"
            )));
        }
        // Check the length the header implies before allocating anything it asks for.
        let rec = record_len(goals) as u64;
        let per_frame = (u64::from(keep_laser) * LASER_BEAMS as u64
            + u64::from(keep_depth) * DEPTH_LEN as u64)
            * 2;
        let expect = 8 + 4 * 8 + 2 + u64::from(goals) + slots * per_frame + count * rec;
        if len != expect {
            return Err(io_err(format!(
                "the header implies {expect} bytes, the file has {len}: truncated or corrupt"
            )));
        }
        let mut buf = ReplayBuffer::new(capacity, (slots - cap) as usize, keep_laser, keep_depth)
            .with_goals(goals)
            .with_envs(envs, n_step);
        if buf.frame_slots as u64 != slots {
            return Err(io_err("replay frame reserve too small".into()));
        }
        buf.frames_pushed = pushed;
        let mut bytes = vec![0u8; 1 << 20];
        for chunk in [&mut buf.laser_mm, &mut buf.depth_mm] {
            for part in chunk.chunks_mut(1 << 19) {
                let b = &mut bytes[..part.len() * 2];
                r.read_exact(b)?;
                for (v, c) in part.iter_mut().zip(b.chunks_exact(2)) {
                    *v = u16::from_le_bytes([c[0], c[1]]);
                }
            }
        }
        let mut b = vec![0u8; record_len(goals)];
        for _ in 0..count {
            r.read_exact(&mut b)?;
            let id =
                |k: usize| u64::from_le_bytes(b[8 * k..8 * k + 8].try_into().unwrap_or([0; 8]));
            let f32_at = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap_or([0; 4]));
            let base = 8 * 2 * FRAME_STACK;
            let goal_at = |k: usize| base + 6 + 4 * (2 * ODOM_HISTORY + k);
            let t = Transition {
                obs: [id(0), id(1), id(2), id(3)],
                next: [id(4), id(5), id(6), id(7)],
                action: b[base],
                reward: f32_at(base + 1),
                terminated: b[base + 5] & 1 == 1,
                steps: (b[base + 5] >> 1) + 1,
                odom: std::array::from_fn(|k| f32_at(base + 6 + 4 * k)),
                goal: std::array::from_fn(|k| if goals { f32_at(goal_at(k)) } else { 0.0 }),
                next_goal: std::array::from_fn(|k| {
                    if goals { f32_at(goal_at(GOAL_DIM + k)) } else { 0.0 }
                }),
            };
            // In order, up to the interleaving of several environments' (`with_envs`).
            let in_order = buf
                .transitions
                .back()
                .is_none_or(|p| p.oldest_frame() <= t.oldest_frame() + buf.frame_margin);
            // s' is s moved on by `steps` frames (none shared after four).
            let k = usize::from(t.steps);
            let chained = k >= FRAME_STACK || t.next[..FRAME_STACK - k] == t.obs[k..];
            if !buf.is_live(&t) || t.action as usize >= 10 || !in_order || !chained {
                return Err(io_err(
                    "replay transitions are out of order or refer to frames the file does not hold"
                        .into(),
                ));
            }
            buf.transitions.push_back(t);
        }
        let mut extra = [0u8; 1];
        if r.read(&mut extra)? != 0 {
            return Err(io_err("trailing bytes after the replay data".into()));
        }
        Ok(buf)
    }
}
