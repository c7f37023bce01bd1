//! Reading a server's response: the answer text and finish reason of a success body (or why it
//! holds none), `Retry-After`, and the short previews of bodies that errors quote.

use serde_json::Value;

use super::RequestKind;

/// Characters of an error body kept in [`LlmError::Http`](super::LlmError::Http).
const BODY_PREVIEW_CHARS: usize = 300;

/// What the client writes as the finish reason of an answer whose server reported none, so that
/// such entries are told apart from entries of versions that did not record it.
pub const FINISH_UNREPORTED: &str = "unreported";

/// Why a success response holds no usable answer.
#[derive(Debug, thiserror::Error)]
pub(super) enum BadAnswer {
    #[error("body is not JSON ({source}): {preview}")]
    NotJson {
        source: serde_json::Error,
        /// The start of the body.
        preview: String,
    },
    #[error("no choices in response: {preview}")]
    NoChoices {
        /// The start of the body.
        preview: String,
    },
    #[error("{field} is missing or not a string: {preview}")]
    NoText {
        /// Where the answer should be (`choices[0].text`...).
        field: &'static str,
        /// The start of the first choice.
        preview: String,
    },
}

/// `finish_reason` values that mean the token limit cut the answer: OpenAI's, vLLM's, llama.cpp's
/// and Ollama's `length` on both endpoints, and `max_tokens` of some proxies.
pub(super) fn cut_off(finish_reason: &str) -> bool {
    matches!(finish_reason, "length" | "max_tokens")
}

/// `Retry-After` as delay-seconds (decimals accepted). The HTTP-date form is not parsed; such a
/// response falls back to the computed backoff.
pub(super) fn parse_retry_after(value: &str) -> Option<f64> {
    value
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|s| s.is_finite() && *s >= 0.0)
}

pub(super) fn parse_answer(kind: RequestKind, bytes: &[u8]) -> Result<(String, String), BadAnswer> {
    let value: Value = serde_json::from_slice(bytes).map_err(|source| BadAnswer::NotJson {
        source,
        preview: preview(&String::from_utf8_lossy(bytes)),
    })?;
    let Some(choice) = value
        .get("choices")
        .and_then(Value::as_array)
        .and_then(|c| c.first())
    else {
        return Err(BadAnswer::NoChoices {
            preview: preview(&value.to_string()),
        });
    };
    let (field, text) = match kind {
        RequestKind::Chat => (
            "choices[0].message.content",
            choice.pointer("/message/content"),
        ),
        RequestKind::Completion => ("choices[0].text", choice.get("text")),
    };
    let Some(text) = text.and_then(Value::as_str) else {
        return Err(BadAnswer::NoText {
            field,
            preview: preview(&choice.to_string()),
        });
    };
    // Both endpoints put `finish_reason` on the choice; a server that sends none (or null) gets
    // FINISH_UNREPORTED, so its answers are not taken for entries of older versions.
    let finish_reason = choice
        .get("finish_reason")
        .and_then(Value::as_str)
        .unwrap_or(FINISH_UNREPORTED);
    Ok((text.to_string(), finish_reason.to_string()))
}

pub(super) fn preview(text: &str) -> String {
    let mut p: String = text.chars().take(BODY_PREVIEW_CHARS).collect();
    if p.len() < text.len() {
        p.push('…');
    }
    p
}
