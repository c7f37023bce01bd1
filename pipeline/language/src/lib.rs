//! The language side of motionforge: what texts say and how they change with the motion.
//!
//! * [`text`]: caption mirroring (left/right, clockwise family) and its side words.
//! * [`compose_text`]: the texts of synthetic simultaneous pairs.
//! * [`caption`]: HumanML3D's caption lines (spaCy's tokens, tags and lemmas).
//! * [`parts`]: SINC's body parts ([`parts::PartSet`]), the embedded labeller and its lexicon, the
//!   parsing of an LLM's part answer, and the parts a motion moves.
//!
//! # A clip's way through this crate
//!
//! Step 2: the clip's texts are labelled by body part ([`parts::lexicon::label_text`]), mirrored with its
//! motion ([`text::mirror_text`]), composed for synthetic pairs ([`compose_text`]) and tagged for
//! HumanML3D's caption files ([`caption::caption_line`]).

pub mod caption;
pub mod compose_text;
pub mod parts;
pub mod text;
