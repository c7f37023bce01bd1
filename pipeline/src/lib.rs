//! motionforge: a dataset builder for text-to-motion research.
pub mod motion;
