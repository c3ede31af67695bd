//! Training MDRLAT agents (SPEC §4, paper Algorithm 1).
//!
//! The learning rule ([`learner`]), the replay buffer ([`replay`]) and the loop that ties
//! them to the simulator ([`train`]) are separate rooms, as in Stable-Baselines3.

pub mod adam;
pub mod bench;
pub mod checkpoint;
pub mod config;
pub mod export;
pub mod learner;
pub mod policy;
pub mod replay;
pub mod tensorboard;
pub mod train;

pub use config::{TrainConfig, TrainConfigError};
pub use learner::{Inputs, Learner, Losses};
pub use policy::{GreedyPolicy, observation_inputs};
pub use replay::{Batch, DepthFrames, DepthLayout, ReplayBuffer, Transition};
pub use train::{Evaluation, Status, Timing, TrainError, TrainReport, evaluate, train};
