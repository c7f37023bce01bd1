//! HumanML3D caption lines: tokens, tags and lemmas against spaCy as the independent reference.
