//! `paraphrase` and `plan`: LLM text augmentation of action texts (LINGO B.1.6 and appendix C).
//! Both run through the response cache; with no LLM configured they use cached answers only and
//! say in the build report what they skipped.

use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};

use crate::config::OnInvalid;
use motionforge_core::base::Tally;
use motionforge_core::progress::ProgressSink;
use motionforge_llm::Unanswered;
use motionforge_llm::cache::ResponseCache;
use motionforge_llm::client::{LlmClient, LlmConfig, LlmError, RequestEvent};
use motionforge_llm::paraphrase::{ParaphraseFault, check_paraphrases};
use motionforge_llm::plans::{PlanStep, parse_task_plan, repair_message};
use motionforge_llm::prompt::{PromptError, Prompts};

/// Why an LLM answer (a paraphrase line, a task plan, a part list, a pair verdict) failed its
/// check: the reason codes of [`AnswerChecks::rejected_by_reason`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AnswerFault {
    /// A paraphrase line refused by `llm::paraphrase`'s checks.
    Paraphrase(ParaphraseFault),
    /// An answer holding no line.
    Empty,
    /// A pair verdict other than yes or no.
    NotYesOrNo,
    /// A task plan still invalid after one repair.
    InvalidPlan,
    /// A part list naming no part.
    NoPart,
    /// A part list naming a part not on the list.
    OffList,
}

impl motionforge_core::base::Named for AnswerFault {
    const ALL: &'static [AnswerFault] = &[
        AnswerFault::Paraphrase(ParaphraseFault::Markup),
        AnswerFault::Paraphrase(ParaphraseFault::Url),
        AnswerFault::Paraphrase(ParaphraseFault::Code),
        AnswerFault::Paraphrase(ParaphraseFault::NotEnglish),
        AnswerFault::Paraphrase(ParaphraseFault::TooShort),
        AnswerFault::Paraphrase(ParaphraseFault::TooLong),
        AnswerFault::Paraphrase(ParaphraseFault::BeyondCount),
        AnswerFault::Paraphrase(ParaphraseFault::Duplicate),
        AnswerFault::Paraphrase(ParaphraseFault::Sides),
        AnswerFault::Paraphrase(ParaphraseFault::Turning),
        AnswerFault::Paraphrase(ParaphraseFault::Action),
        AnswerFault::Empty,
        AnswerFault::NotYesOrNo,
        AnswerFault::InvalidPlan,
        AnswerFault::NoPart,
        AnswerFault::OffList,
    ];

    fn name(self) -> &'static str {
        match self {
            AnswerFault::Paraphrase(fault) => fault.code(),
            AnswerFault::Empty => "empty",
            AnswerFault::NotYesOrNo => "not_yes_or_no",
            AnswerFault::InvalidPlan => "invalid_plan",
            AnswerFault::NoPart => "no_part",
            AnswerFault::OffList => "off_list",
        }
    }
}

impl std::fmt::Display for AnswerFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(motionforge_core::base::Named::name(*self))
    }
}

/// How a stage's LLM answers fared against its checks, for the build report: what passed, what
/// failed by reason, and what the stage's `on_invalid` policy made of the failures.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct AnswerChecks {
    /// Answers that passed (for paraphrases: lines).
    pub accepted: usize,
    /// Answers (lines) that failed, by reason code (`markup`, `off_list`, `invalid_plan`, ...).
    pub rejected_by_reason: Tally<AnswerFault>,
    /// Failed answers replaced by the embedded labeller's.
    pub fell_back: usize,
    /// Failed answers not used.
    pub dropped: usize,
    /// Failed answers used anyway (`on_invalid = "keep"`).
    pub kept: usize,
    /// Answers cut off by the token limit (also after the retry with more tokens): failed
    /// requests, never cached.
    pub truncated: usize,
}

impl AnswerChecks {
    /// Counts one failed answer under `reason`.
    pub fn reject(&mut self, reason: AnswerFault) {
        self.rejected_by_reason.add(reason);
    }

    /// Answers that failed their checks.
    pub fn rejected(&self) -> usize {
        self.rejected_by_reason.total()
    }
}

/// What a text-augmentation stage did, for the build report.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct AugmentReport {
    /// Unique texts the stage covers.
    pub texts: usize,
    /// Texts answered (cache or LLM).
    pub answered: usize,
    /// Requests sent (repairs included).
    pub requests: usize,
    /// Texts whose answer was asked of the LLM this run rather than found in the cache.
    #[serde(default)]
    pub asked: usize,
    /// Texts skipped, by reason (no LLM configured, offline cache miss, request failed).
    pub skipped: BTreeMap<String, usize>,
    /// Answers rejected after parsing (and repair, for plans): text and reason.
    pub rejected: Vec<(String, String)>,
    /// The checks' counts: accepted, rejected by reason, and what the policy did.
    #[serde(default)]
    pub checks: AnswerChecks,
}

/// Why a text-augmentation stage stops the build.
#[derive(Debug, thiserror::Error)]
pub enum AugmentError {
    /// A prompt does not render.
    #[error(transparent)]
    Prompt(#[from] PromptError),
    /// The server is gone (the probe found nothing, or the circuit breaker opened).
    #[error("{stage}: {error}")]
    Server {
        /// The stage.
        stage: String,
        /// The client's error.
        error: LlmError,
    },
}

/// Where an LLM stage reports its requests: the stage's name and the build's progress.
#[derive(Debug, Clone, Copy)]
pub struct Asking<'a> {
    /// The stage name (`paraphrase`, `plan`, `pair_check`, `label`).
    pub stage: &'a str,
    /// The build's progress receiver.
    pub progress: &'a ProgressSink,
}

impl Asking<'_> {
    /// The observer handed to the client: the stage's bar counts the prompts sent.
    pub fn observe(&self, event: RequestEvent) {
        match event {
            RequestEvent::Sending { to_send, .. } if to_send > 0 => {
                self.progress.requests_started(self.stage, to_send as u64);
            }
            RequestEvent::Sending { .. } => {}
            RequestEvent::Finished { ok } => {
                // The failure first, so the progress line of this request counts it.
                if !ok {
                    self.progress.failed(self.stage, 1);
                }
                self.progress.advanced(self.stage, 1);
            }
        }
    }
}

/// The build's one LLM client, made when the first request is to be sent (never offline) and
/// shared by every LLM stage after it: one rate limit and one circuit breaker per build, as the
/// server sees one client.
#[derive(Debug, Default)]
pub struct Connection(std::cell::OnceCell<Result<LlmClient, LlmError>>);

impl Connection {
    /// The client for `config`, made on first use (or why it cannot be made).
    pub fn client(&self, config: &LlmConfig) -> Result<&LlmClient, &LlmError> {
        self.0
            .get_or_init(|| LlmClient::new(config.clone()))
            .as_ref()
    }
}

/// Where an LLM stage's prompts go and how it reports them: the server (`None` without
/// `[llm]`) and the build's client for it, whether only the cache may answer (`--offline`), the
/// response cache, and the stage's name and progress.
pub struct Asker<'a> {
    /// The server's settings.
    pub llm: Option<&'a LlmConfig>,
    /// The build's client.
    pub connection: &'a Connection,
    /// Answers from the cache only.
    pub offline: bool,
    /// The response cache (`None` without `[llm]`).
    pub cache: Option<&'a mut ResponseCache>,
    /// Where requests are reported.
    pub asking: Asking<'a>,
}

impl Asker<'_> {
    /// The same asker for one more round of requests (a plan's repairs).
    fn again(&mut self) -> Asker<'_> {
        Asker {
            llm: self.llm,
            connection: self.connection,
            offline: self.offline,
            cache: self.cache.as_deref_mut(),
            asking: self.asking,
        }
    }
}

/// Answers for `prompts`: from the cache when offline or without a server, else asked. A server
/// that is gone stops the stage with the client's error.
pub(crate) fn answers(
    prompts: &[String],
    ask: Asker<'_>,
    report: &mut AugmentReport,
) -> Result<Vec<Option<String>>, AugmentError> {
    let Asker {
        llm,
        connection,
        offline,
        cache,
        asking,
    } = ask;
    let (Some(cfg), Some(cache)) = (llm, cache) else {
        *report
            .skipped
            .entry(Unanswered::NoLlm.to_string())
            .or_insert(0) += prompts.len();
        return Ok(vec![None; prompts.len()]);
    };
    if offline {
        return Ok(prompts
            .iter()
            .map(|p| {
                let hit = cache.get(&cfg.cache_key(p)).map(str::to_string);
                if hit.is_none() {
                    *report
                        .skipped
                        .entry(Unanswered::Offline.to_string())
                        .or_insert(0) += 1;
                }
                hit
            })
            .collect());
    }
    let client = match connection.client(cfg) {
        Ok(c) => c,
        Err(e) => {
            *report
                .skipped
                .entry(Unanswered::Client(e.to_string()).to_string())
                .or_insert(0) += prompts.len();
            return Ok(vec![None; prompts.len()]);
        }
    };
    let results = client.complete_all_observed(prompts, cache, &|e| asking.observe(e));
    let mut out = Vec::with_capacity(results.len());
    for r in results {
        match r {
            Ok(a) => {
                report.requests += usize::from(!a.from_cache);
                report.asked += usize::from(!a.from_cache);
                out.push(Some(a.text));
            }
            Err(e) if e.stops_stage() => {
                return Err(AugmentError::Server {
                    stage: asking.stage.to_string(),
                    error: e,
                });
            }
            Err(e) => {
                if matches!(e, LlmError::Truncated { .. }) {
                    report.checks.truncated += 1;
                }
                *report
                    .skipped
                    .entry(Unanswered::RequestFailed(e.to_string()).to_string())
                    .or_insert(0) += 1;
                out.push(None);
            }
        }
    }
    Ok(out)
}

/// Paraphrases of every text, each answer checked line by line (`llm::paraphrase`): the lines
/// kept per normalised text. Refused lines are dropped, or kept with `on_invalid = "keep"`
/// (duplicates never are); both are counted in `report.checks`.
pub fn paraphrase(
    texts: &BTreeSet<String>,
    n: usize,
    on_invalid: OnInvalid,
    prompts: &Prompts,
    ask: Asker<'_>,
    report: &mut AugmentReport,
) -> Result<BTreeMap<String, Vec<String>>, AugmentError> {
    let texts: Vec<&String> = texts.iter().collect();
    report.texts = texts.len();
    let rendered: Vec<String> = texts
        .iter()
        .map(|t| prompts.paraphrase(t, n))
        .collect::<Result<_, _>>()?;
    let mut out = BTreeMap::new();
    for (t, answer) in texts.iter().zip(answers(&rendered, ask, report)?) {
        let Some(answer) = answer else { continue };
        report.answered += 1;
        let checked = check_paraphrases(t, &answer, n);
        if checked.lines.is_empty() {
            // Small models answer nothing at all; that is a failed answer too, not a quiet one.
            report.checks.reject(AnswerFault::Empty);
            report.checks.dropped += 1;
            report
                .rejected
                .push(((*t).clone(), "the answer holds no line".into()));
        }
        let mut kept = Vec::new();
        for (line, fault) in checked.lines {
            let Some(fault) = fault else {
                report.checks.accepted += 1;
                kept.push(line);
                continue;
            };
            report.checks.reject(AnswerFault::Paraphrase(fault));
            report
                .rejected
                .push((format!("{t} -> {line}"), fault.to_string()));
            if on_invalid == OnInvalid::Keep && fault != ParaphraseFault::Duplicate {
                report.checks.kept += 1;
                kept.push(line);
            } else {
                report.checks.dropped += 1;
            }
        }
        out.insert((*t).clone(), kept);
    }
    Ok(out)
}

/// Pairs an LLM says a person cannot do at once (SINC's optional semantic check): `pair_compat`
/// asked once per pair of normalised texts, through the cache. Pairs without an answer are not
/// vetoed; the report counts them as skipped.
pub fn incompatible_pairs(
    pairs: &[(String, String)],
    prompts: &Prompts,
    ask: Asker<'_>,
    report: &mut AugmentReport,
) -> Result<BTreeSet<(String, String)>, AugmentError> {
    report.texts = pairs.len();
    let rendered: Vec<String> = pairs
        .iter()
        .map(|(a, b)| prompts.pair_compat(a, b))
        .collect::<Result<_, _>>()?;
    let mut out = BTreeSet::new();
    for (pair, answer) in pairs.iter().zip(answers(&rendered, ask, report)?) {
        let Some(answer) = answer else { continue };
        report.answered += 1;
        let first = answer
            .trim()
            .trim_start_matches(|c: char| !c.is_alphabetic())
            .to_lowercase();
        let word: String = first.chars().take_while(|c| c.is_alphabetic()).collect();
        if word == "no" {
            report.checks.accepted += 1;
            out.insert(pair.clone());
        } else if word == "yes" {
            report.checks.accepted += 1;
        } else {
            report.checks.reject(AnswerFault::NotYesOrNo);
            report.checks.dropped += 1;
            report.rejected.push((
                format!("{} + {}", pair.0, pair.1),
                format!("answer is neither yes nor no: `{}`", answer.trim()),
            ));
        }
    }
    Ok(out)
}

/// Task plans of every text; an invalid plan is asked once more with a repair message, then
/// rejected with its reason.
pub fn plan(
    texts: &BTreeSet<String>,
    prompts: &Prompts,
    mut ask: Asker<'_>,
    report: &mut AugmentReport,
) -> Result<BTreeMap<String, Vec<PlanStep>>, AugmentError> {
    let texts: Vec<&String> = texts.iter().collect();
    report.texts = texts.len();
    let rendered: Vec<String> = texts
        .iter()
        .map(|t| prompts.task_plan(t))
        .collect::<Result<_, _>>()?;
    let first = answers(&rendered, ask.again(), report)?;
    let mut out = BTreeMap::new();
    let mut repairs: Vec<(usize, String)> = Vec::new();
    for (i, answer) in first.iter().enumerate() {
        let Some(answer) = answer else { continue };
        match parse_task_plan(answer) {
            Ok(steps) => {
                report.answered += 1;
                report.checks.accepted += 1;
                out.insert(texts[i].clone(), steps);
            }
            Err(e) => repairs.push((
                i,
                format!("{}\n{}\n\n{}", rendered[i], answer, repair_message(&e)),
            )),
        }
    }
    if !repairs.is_empty() {
        let again: Vec<String> = repairs.iter().map(|(_, p)| p.clone()).collect();
        let mut repair_report = AugmentReport::default();
        let repaired = answers(&again, ask, &mut repair_report)?;
        report.checks.truncated += repair_report.checks.truncated;
        for ((i, _), answer) in repairs.iter().zip(repaired) {
            report.requests += repair_report.requests;
            repair_report.requests = 0;
            let result = answer
                .ok_or_else(|| "no answer to the repair request".to_string())
                .and_then(|a| parse_task_plan(&a).map_err(|e| e.to_string()));
            match result {
                Ok(steps) => {
                    report.answered += 1;
                    report.checks.accepted += 1;
                    out.insert(texts[*i].clone(), steps);
                }
                Err(reason) => {
                    report.checks.reject(AnswerFault::InvalidPlan);
                    report.checks.dropped += 1;
                    report.rejected.push((
                        texts[*i].clone(),
                        format!("invalid plan after one repair: {reason}"),
                    ));
                }
            }
        }
    }
    Ok(out)
}
