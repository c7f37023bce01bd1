//! `label`: body parts for every clip. Each unique normalised text is labelled once: by the
//! embedded labeller (lexicon, then the clip's part velocities when the lexicon does not know the
//! text), or by the LLM through the response cache with SINC's prompt. Every label records which
//! labeller produced it.

use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};

use crate::config::{Labeller, OnInvalid, OnMiss, PartLabelConfig};
use crate::stages::augment::{AnswerChecks, AnswerFault, Asking};
use motionforge_core::motion::Profile;
use motionforge_language::parts::answer::parse_part_answer;
use motionforge_language::parts::lexicon::label_text;
use motionforge_language::parts::velocity::motion_parts;
use motionforge_language::parts::{LabelSource, LabelSources, PartSet};
use motionforge_llm::Unanswered;
use motionforge_llm::cache::ResponseCache;
use motionforge_llm::client::{LlmConfig, LlmError};
use motionforge_llm::prompt::{PromptError, Prompts};
use motionforge_sources::clip::{Clip, LoadedClip, SourceKind};

/// Stage name.
pub const NAME: &str = "label";

/// How texts are compared and asked: lowercase, single spaces, trimmed.
pub fn normalize_text(text: &str) -> String {
    text.to_lowercase()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

/// The label of one text.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TextParts {
    /// Parts; `None` when the labeller had no answer (embedded: text unknown, the clip's motion
    /// decides; LLM: an answer with no part at all).
    pub parts: Option<PartSet>,
    /// The labeller that answered.
    pub source: LabelSource,
    /// Why the answer needs a look (off-list words, no part), if it does.
    pub flag: Option<String>,
    /// The answer failed its checks and `on_invalid = "drop"`: the text's clips get no parts.
    // Skipped when false so the label fingerprint of builds without drops stays as it was.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub dropped: bool,
}

/// What the stage did, for the build report.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct LabelReport {
    /// Unique texts labelled.
    pub texts: usize,
    /// Requests sent to the LLM.
    pub requests: usize,
    /// Answers found in the cache.
    pub cache_hits: usize,
    /// Clips per label source.
    pub sources: BTreeMap<String, usize>,
    /// Flagged answers: text and reason.
    pub flagged: Vec<(String, String)>,
    /// Texts the LLM could not answer (after retries) or the cache lacked, with the reason.
    pub missing: Vec<(String, Unanswered)>,
    /// On clips labelled by the lexicon: mean fraction of the six parts on which the motion's
    /// velocity evidence agrees (SINC's baseline), and how many clips that covers.
    pub velocity_agreement: Option<(f64, usize)>,
    /// LLM answers by check outcome (reasons `off_list`, `no_part`) and what `on_invalid` did
    /// with the flagged ones.
    #[serde(default)]
    pub checks: AnswerChecks,
}

/// Why labelling stops the build.
#[derive(Debug, thiserror::Error)]
pub enum LabelError {
    /// A prompt does not render.
    #[error(transparent)]
    Prompt(#[from] PromptError),
    /// `on_miss = "fail"` and some texts have no answer.
    #[error("{} texts have no cached LLM answer and cannot be asked ({}): {}", texts.len(), reason, preview(texts))]
    Missing {
        /// Why they cannot be asked (the first text's reason).
        reason: Unanswered,
        /// The texts.
        texts: Vec<String>,
    },
    /// The LLM client cannot be created.
    #[error("LLM client: {0}")]
    Client(#[source] LlmError),
    /// The server is gone (the probe found nothing, or the circuit breaker opened).
    #[error("label: {0}")]
    Server(LlmError),
}

fn preview(texts: &[String]) -> String {
    let shown: Vec<&str> = texts.iter().take(10).map(String::as_str).collect();
    let more = texts.len().saturating_sub(shown.len());
    format!(
        "{}{}",
        shown.join("; "),
        if more > 0 {
            format!("; and {more} more")
        } else {
            String::new()
        }
    )
}

/// Everything the stage needs.
pub struct LabelInput<'a> {
    /// Stage settings.
    pub config: &'a PartLabelConfig,
    /// The LLM server, if configured.
    pub llm: Option<&'a LlmConfig>,
    /// The build's client for it.
    pub connection: &'a crate::stages::augment::Connection,
    /// Prompt templates.
    pub prompts: &'a Prompts,
    /// Force offline (the build's `--offline`).
    pub offline: bool,
    /// Where requests are reported.
    pub progress: &'a motionforge_core::progress::ProgressSink,
}

fn embedded(text: &str) -> TextParts {
    let l = label_text(text);
    TextParts {
        parts: l.known.then_some(l.parts),
        source: LabelSource::Lexicon,
        flag: None,
        dropped: false,
    }
}

/// Labels every unique text of `clips` (their `texts`).
pub fn label_texts(
    clips: &[&Clip],
    input: &LabelInput<'_>,
    cache: Option<&mut ResponseCache>,
    report: &mut LabelReport,
) -> Result<BTreeMap<String, TextParts>, LabelError> {
    let texts: BTreeSet<String> = clips
        .iter()
        .flat_map(|c| c.texts.iter().map(|t| normalize_text(t)))
        .collect();
    let texts: Vec<String> = texts.into_iter().collect();
    report.texts = texts.len();
    let mut out = BTreeMap::new();
    let (cfg, cache) = match (input.config.labeller, input.llm, cache) {
        (Labeller::Embedded, _, _) => {
            for t in texts {
                out.insert(t.clone(), embedded(&t));
            }
            return Ok(out);
        }
        (Labeller::Llm, Some(cfg), Some(cache)) => (cfg, cache),
        (Labeller::Llm, _, _) => {
            return fallback_all(
                &texts,
                input.config.on_miss,
                Unanswered::NoLlmSection,
                report,
            );
        }
    };
    let prompts: Vec<String> = texts
        .iter()
        .map(|t| input.prompts.part_labels(t, input.config.variant))
        .collect::<Result<_, _>>()?;
    let offline = input.offline || input.config.offline;
    let (answers, missing) = if offline {
        cached_answers(&texts, &prompts, cfg, cache, report)
    } else {
        asked_answers(&texts, &prompts, cfg, cache, input, report)?
    };
    if !missing.is_empty() && input.config.on_miss == OnMiss::Fail {
        return Err(LabelError::Missing {
            reason: missing[0].1.clone(),
            texts: missing.into_iter().map(|(t, _)| t).collect(),
        });
    }
    for (t, answer) in texts.iter().zip(answers) {
        let label = match answer {
            Some((text, source)) => {
                checked_answer(t, &text, source, input.config.on_invalid, report)
            }
            None => embedded(t),
        };
        out.insert(t.clone(), label);
    }
    report.missing = missing;
    Ok(out)
}

/// Each text's answer and its labeller, in text order (`None`: unanswered).
type Answers = Vec<Option<(String, LabelSource)>>;
/// The texts left unanswered, and why.
type Missing = Vec<(String, Unanswered)>;

/// Offline: each text's answer from the response cache alone.
fn cached_answers(
    texts: &[String],
    prompts: &[String],
    cfg: &LlmConfig,
    cache: &ResponseCache,
    report: &mut LabelReport,
) -> (Answers, Missing) {
    let mut answers: Answers = Vec::with_capacity(texts.len());
    let mut missing: Missing = Vec::new();
    for (t, p) in texts.iter().zip(prompts) {
        match cache.get_entry(&cfg.cache_key(p)) {
            Some(e) => {
                report.cache_hits += 1;
                answers.push(Some((e.response.clone(), source_name(&e.source, cfg))));
            }
            None => {
                missing.push((t.clone(), Unanswered::Offline));
                answers.push(None);
            }
        }
    }
    (answers, missing)
}

/// Each text's answer from the LLM server (through the response cache); a server that is gone
/// stops the stage.
fn asked_answers(
    texts: &[String],
    prompts: &[String],
    cfg: &LlmConfig,
    cache: &mut ResponseCache,
    input: &LabelInput<'_>,
    report: &mut LabelReport,
) -> Result<(Answers, Missing), LabelError> {
    let mut answers: Answers = Vec::with_capacity(texts.len());
    let mut missing: Missing = Vec::new();
    let client = input
        .connection
        .client(cfg)
        .map_err(|e| LabelError::Client(e.clone()))?;
    let asking = Asking {
        stage: NAME,
        progress: input.progress,
    };
    let results = client.complete_all_observed(prompts, cache, &|e| asking.observe(e));
    if let Some(Err(e)) = results
        .iter()
        .find(|r| r.as_ref().is_err_and(LlmError::stops_stage))
    {
        return Err(LabelError::Server(e.clone()));
    }
    for ((t, p), result) in texts.iter().zip(prompts).zip(results) {
        match result {
            Ok(a) => {
                if a.from_cache {
                    report.cache_hits += 1;
                } else {
                    report.requests += 1;
                }
                let source = cache
                    .get_entry(&cfg.cache_key(p))
                    .map(|e| e.source.clone())
                    .unwrap_or_default();
                answers.push(Some((a.text, source_name(&source, cfg))));
            }
            Err(e) => {
                if matches!(e, LlmError::Truncated { .. }) {
                    report.checks.truncated += 1;
                }
                missing.push((t.clone(), Unanswered::RequestFailed(e.to_string())));
                answers.push(None);
            }
        }
    }
    Ok((answers, missing))
}

/// The label of text `t` from the LLM's `answer`: used when it passes the checks, else flagged
/// and replaced as `on_invalid` says (the embedded labeller's, no parts, or kept as it is).
fn checked_answer(
    t: &str,
    answer: &str,
    source: LabelSource,
    on_invalid: OnInvalid,
    report: &mut LabelReport,
) -> TextParts {
    let parsed = parse_part_answer(answer);
    let flag = parsed.is_flagged().then(|| {
        if parsed.empty {
            format!("no body part in the answer `{}`", answer.trim())
        } else {
            format!("words outside the list: {}", parsed.off_list.join(", "))
        }
    });
    let llm = TextParts {
        parts: (!parsed.empty).then_some(parsed.parts),
        source,
        flag: flag.clone(),
        dropped: false,
    };
    let Some(f) = flag else {
        report.checks.accepted += 1;
        return llm;
    };
    report.checks.reject(if parsed.empty {
        AnswerFault::NoPart
    } else {
        AnswerFault::OffList
    });
    report.flagged.push((t.to_string(), f.clone()));
    match on_invalid {
        OnInvalid::Embedded => {
            report.checks.fell_back += 1;
            TextParts {
                flag: Some(f),
                ..embedded(t)
            }
        }
        OnInvalid::Drop => {
            report.checks.dropped += 1;
            TextParts {
                parts: None,
                dropped: true,
                ..llm
            }
        }
        OnInvalid::Keep => {
            report.checks.kept += 1;
            llm
        }
    }
}

/// The labeller of a response-cache entry, from the source the cache recorded with it.
fn source_name(cache_source: &str, cfg: &LlmConfig) -> LabelSource {
    match cache_source.strip_prefix(IMPORT_PREFIX) {
        Some(file) => LabelSource::Import {
            file: file.to_string(),
        },
        None => LabelSource::Llm {
            model: cfg.model.clone(),
        },
    }
}

/// How the response cache records answers imported from a file: `import:<file name>`.
const IMPORT_PREFIX: &str = "import:";

fn fallback_all(
    texts: &[String],
    on_miss: OnMiss,
    reason: Unanswered,
    report: &mut LabelReport,
) -> Result<BTreeMap<String, TextParts>, LabelError> {
    if on_miss == OnMiss::Fail {
        return Err(LabelError::Missing {
            reason,
            texts: texts.to_vec(),
        });
    }
    report.missing = texts.iter().map(|t| (t.clone(), reason.clone())).collect();
    Ok(texts.iter().map(|t| (t.clone(), embedded(t))).collect())
}

/// Puts labels on clips: a single clip takes its text's label (or its motion's velocity evidence
/// when the labeller had none); a real pair takes the union of its texts' labels.
pub fn apply_labels(
    clips: &mut [LoadedClip],
    labels: &BTreeMap<String, TextParts>,
    profile: impl Fn(&Clip) -> Option<Profile>,
    report: &mut LabelReport,
) {
    let mut agreement = (0.0, 0usize);
    for LoadedClip { clip, motion } in clips.iter_mut() {
        let found: Vec<Option<&TextParts>> = clip
            .texts
            .iter()
            .map(|t| labels.get(&normalize_text(t)))
            .collect();
        let all_known = found.iter().all(|f| f.is_some_and(|l| l.parts.is_some()));
        if found.iter().any(|f| f.is_some_and(|l| l.dropped)) {
            // A flagged answer dropped by `on_invalid = "drop"`: no parts, and no guess either.
            clip.parts = None;
            clip.label_source = None;
        } else if all_known && !found.is_empty() {
            let parts = found
                .iter()
                .flatten()
                .filter_map(|l| l.parts)
                .fold(PartSet::default(), |a, b| a | b);
            let sources: LabelSources = found.iter().flatten().map(|l| l.source.clone()).collect();
            clip.parts = Some(parts);
            let lexicon_only = sources.is_only(&LabelSource::Lexicon);
            clip.label_source = Some(sources);
            if clip.kind == SourceKind::RealSingle
                && lexicon_only
                && let Some(p) = profile(clip)
            {
                agreement.0 += motionforge_language::parts::velocity::agreement(
                    parts,
                    motion_parts(motion, &p),
                );
                agreement.1 += 1;
            }
        } else if clip.kind == SourceKind::RealSingle
            && let Some(p) = profile(clip)
        {
            // No answer for the text: the motion itself says which parts move (SINC's baseline).
            clip.parts = Some(motion_parts(motion, &p));
            clip.label_source = Some(LabelSources::one(LabelSource::Velocity));
        } else {
            clip.parts = None;
            clip.label_source = None;
        }
        let key = clip
            .label_source
            .as_ref()
            .map_or_else(|| "(none)".into(), ToString::to_string);
        *report.sources.entry(key).or_insert(0) += 1;
    }
    if agreement.1 > 0 {
        report.velocity_agreement = Some((agreement.0 / agreement.1 as f64, agreement.1));
    }
}

/// What an import did.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ImportReport {
    /// Answers written to the cache.
    pub imported: usize,
    /// Answers already in the cache (same key), left as they were.
    pub already: usize,
    /// Texts whose record had no answer at the requested position.
    pub without_answer: Vec<String>,
    /// Answers using words outside the prompt's list, whether or not a synonym maps them: text
    /// and the words.
    pub outside_list: Vec<(String, String)>,
    /// Answers flagged for a look (words no synonym maps, or no part): text, reason.
    pub flagged: Vec<(String, String)>,
}

/// Why an import fails.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The file is not a JSON object of text -> answers.
    #[error(
        "{file}: expected a JSON object of action text -> [answer, ...] (SINC's gpt3-labels-list.json): {source}"
    )]
    Format {
        /// The file.
        file: String,
        /// The reader's error.
        source: serde_json::Error,
    },
    /// A prompt does not render.
    #[error(transparent)]
    Prompt(#[from] PromptError),
    /// The cache cannot be written.
    #[error(transparent)]
    Cache(#[from] motionforge_llm::cache::CacheError),
}

/// Imports existing answers, SINC's format `{text: [answer_v1, answer_v2, answer_v3]}`, into the
/// response cache under the keys the label stage will look up: the prompt `variant` rendered for
/// each text, with the model and sampling parameters of `llm`. `answer` picks the position in
/// each list (SINC's third answer, index 2, is its Listing 1 prompt).
pub fn import_answers(
    json: &str,
    file: &str,
    answer: usize,
    variant: motionforge_llm::prompt::PartPromptVariant,
    prompts: &Prompts,
    llm: &LlmConfig,
    cache: &mut ResponseCache,
) -> Result<ImportReport, ImportError> {
    let map: BTreeMap<String, Vec<String>> =
        serde_json::from_str(json).map_err(|source| ImportError::Format {
            file: file.to_string(),
            source,
        })?;
    let mut report = ImportReport::default();
    let mut batch: Vec<(
        motionforge_llm::cache::CacheKey,
        motionforge_llm::cache::CacheEntry,
    )> = Vec::new();
    let mut batched: BTreeSet<String> = BTreeSet::new();
    let source = format!(
        "{IMPORT_PREFIX}{}",
        file.rsplit(['/', '\\']).next().unwrap_or(file)
    );
    for (text, answers) in map {
        let Some(a) = answers.get(answer) else {
            report.without_answer.push(text);
            continue;
        };
        let parsed = parse_part_answer(a);
        if parsed.has_raw_off_list() {
            let words: Vec<&str> = parsed
                .synonyms
                .iter()
                .chain(&parsed.off_list)
                .map(String::as_str)
                .collect();
            report.outside_list.push((text.clone(), words.join(", ")));
        }
        if parsed.is_flagged() {
            let why = if parsed.empty {
                "no body part".to_string()
            } else {
                format!("outside the list: {}", parsed.off_list.join(", "))
            };
            report.flagged.push((text.clone(), why));
        }
        let prompt = prompts.part_labels(&normalize_text(&text), variant)?;
        let key = llm.cache_key(&prompt);
        if cache.get(&key).is_some() || !batched.insert(key.as_str().to_string()) {
            report.already += 1;
            continue;
        }
        let entry = motionforge_llm::cache::CacheEntry::new(
            &llm.model,
            llm.kind,
            &prompt,
            &llm.sampling(),
            a.clone(),
            &source,
        );
        batch.push((key, entry));
        report.imported += 1;
    }
    cache.insert_many(batch)?;
    Ok(report)
}
