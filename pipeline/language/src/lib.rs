//! The language side of motionforge: what texts say and how they change with the motion.
//!
//! * [`text`]: caption mirroring (left/right, clockwise family) and its side words.
//! * [`compose_text`]: the texts of synthetic simultaneous pairs.
//! * [`caption`]: HumanML3D's caption lines (spaCy's tokens, tags and lemmas).
//! * [`parts`]: SINC's body parts ([`parts::PartSet`]), the embedded labeller and its lexicon, the
//!   parsing of an LLM's part answer, and the parts a motion moves.

pub mod caption;
pub mod compose_text;
pub mod parts;
pub mod text;
