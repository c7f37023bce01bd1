//! Why an LLM stage has no answer for a text: a typed reason, written in reports as words.

use serde::{Deserialize, Serialize};

/// Why a text got no LLM answer. Reports show it as words (`offline and not in the cache`); code
/// decides on the variant, never on the words.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(into = "String", from = "String")]
pub enum Unanswered {
    /// No `[llm]` section: nothing to ask.
    NoLlm,
    /// `part_labels.labeller = "llm"` without an `[llm]` section.
    NoLlmSection,
    /// Offline (`--offline` or the config's `offline`) and the cache has no answer.
    Offline,
    /// The client could not be created (bad `[llm]` value, unset key variable).
    // The error's text, not the error: read back from the words the stage cache and reports hold.
    Client(String),
    /// The request failed after its last retry.
    // The error's text, not the error: read back from the words the stage cache and reports hold.
    RequestFailed(String),
}

const NO_LLM: &str = "no LLM configured";
const NO_LLM_SECTION: &str = "part_labels.labeller = \"llm\" but the config has no [llm] section";
const OFFLINE: &str = "offline and not in the cache";
const CLIENT: &str = "LLM client: ";
const REQUEST: &str = "request failed: ";

impl Unanswered {
    /// True when asking (online, with an LLM configured) would answer it: a cache miss, not a
    /// failure.
    pub fn is_offline_miss(&self) -> bool {
        matches!(self, Unanswered::Offline)
    }

    /// True when a request was tried and failed (a reject), as opposed to nothing being asked.
    pub fn is_failure(&self) -> bool {
        matches!(self, Unanswered::Client(_) | Unanswered::RequestFailed(_))
    }
}

impl std::fmt::Display for Unanswered {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Unanswered::NoLlm => f.write_str(NO_LLM),
            Unanswered::NoLlmSection => f.write_str(NO_LLM_SECTION),
            Unanswered::Offline => f.write_str(OFFLINE),
            Unanswered::Client(e) => write!(f, "{CLIENT}{e}"),
            Unanswered::RequestFailed(e) => write!(f, "{REQUEST}{e}"),
        }
    }
}

impl From<Unanswered> for String {
    fn from(u: Unanswered) -> String {
        u.to_string()
    }
}

/// Reads the words back (the stage cache and `build-report.json` hold them).
impl From<String> for Unanswered {
    fn from(s: String) -> Unanswered {
        match s.as_str() {
            NO_LLM => Unanswered::NoLlm,
            NO_LLM_SECTION => Unanswered::NoLlmSection,
            OFFLINE => Unanswered::Offline,
            _ => match (s.strip_prefix(CLIENT), s.strip_prefix(REQUEST)) {
                (Some(e), _) => Unanswered::Client(e.to_string()),
                (_, Some(e)) => Unanswered::RequestFailed(e.to_string()),
                _ => Unanswered::RequestFailed(s),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_round_trip() {
        for u in [
            Unanswered::NoLlm,
            Unanswered::NoLlmSection,
            Unanswered::Offline,
            Unanswered::Client("no key".into()),
            Unanswered::RequestFailed("HTTP 500".into()),
        ] {
            assert_eq!(Unanswered::from(u.to_string()), u);
            let json = serde_json::to_string(&u).unwrap();
            assert_eq!(serde_json::from_str::<Unanswered>(&json).unwrap(), u);
        }
    }
}
