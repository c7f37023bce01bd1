//! What comes into a motionforge build, read into common forms before any stage runs.
//!
//! * [`annotate`]: annotation formats (file names and sidecars, BABEL, LINGO-style event logs,
//!   HumanML3D's index and texts) read as labelled time spans per capture
//!   ([`annotate::span::CaptureAnnotation`]), and the motion-type taxonomy.
//! * [`amass`]: AMASS `.npz` pose files through the user's SMPL-H or SMPL-X body model.
//! * [`clip`]: [`clip::Capture`] (a read capture) and [`clip::Clip`] (one row's metadata: texts,
//!   provenance, parts, skeleton; no frames), and [`clip::LoadedClip`] (a clip with its motion).
//!
//! # A clip's way through this crate
//!
//! Step 4: the capture's annotation ([`annotate`]) gives the labelled spans it is cut by, an AMASS
//! file becomes a motion through the body model ([`amass`]), and each cut becomes a
//! [`clip::Clip`], the record every later crate passes along.

pub mod amass;
pub mod annotate;
pub mod clip;
