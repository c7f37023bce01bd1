//! `paraphrase` and `plan`: LLM text augmentation of action texts (LINGO B.1.6 and appendix C).
//! Both run through the response cache; with no LLM configured they use cached answers only and
//! say in the build report what they skipped.

use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};

use crate::llm::Unanswered;
use crate::llm::cache::ResponseCache;
use crate::llm::client::{LlmClient, LlmConfig};
use crate::llm::plans::{PlanStep, parse_paraphrases, parse_task_plan, repair_message};
use crate::llm::prompt::{PromptError, Prompts};

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
}

/// Answers for `prompts`: from the cache when offline or without a server, else asked.
pub(crate) fn answers(
    prompts: &[String],
    llm: Option<&LlmConfig>,
    offline: bool,
    cache: Option<&mut ResponseCache>,
    report: &mut AugmentReport,
) -> Vec<Option<String>> {
    let (Some(cfg), Some(cache)) = (llm, cache) else {
        *report
            .skipped
            .entry(Unanswered::NoLlm.to_string())
            .or_insert(0) += prompts.len();
        return vec![None; prompts.len()];
    };
    if offline {
        return prompts
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
            .collect();
    }
    let client = match LlmClient::new(cfg.clone()) {
        Ok(c) => c,
        Err(e) => {
            *report
                .skipped
                .entry(Unanswered::Client(e.to_string()).to_string())
                .or_insert(0) += prompts.len();
            return vec![None; prompts.len()];
        }
    };
    client
        .complete_all(prompts, cache)
        .into_iter()
        .map(|r| match r {
            Ok(a) => {
                report.requests += usize::from(!a.from_cache);
                report.asked += usize::from(!a.from_cache);
                Some(a.text)
            }
            Err(e) => {
                *report
                    .skipped
                    .entry(Unanswered::RequestFailed(e.to_string()).to_string())
                    .or_insert(0) += 1;
                None
            }
        })
        .collect()
}

/// Paraphrases of every text: accepted alternatives per normalised text.
pub fn paraphrase(
    texts: &BTreeSet<String>,
    n: usize,
    prompts: &Prompts,
    llm: Option<&LlmConfig>,
    offline: bool,
    cache: Option<&mut ResponseCache>,
    report: &mut AugmentReport,
) -> Result<BTreeMap<String, Vec<String>>, PromptError> {
    let texts: Vec<&String> = texts.iter().collect();
    report.texts = texts.len();
    let rendered: Vec<String> = texts
        .iter()
        .map(|t| prompts.paraphrase(t, n))
        .collect::<Result<_, _>>()?;
    let mut out = BTreeMap::new();
    for (t, answer) in texts
        .iter()
        .zip(answers(&rendered, llm, offline, cache, report))
    {
        let Some(answer) = answer else { continue };
        report.answered += 1;
        let parsed = parse_paraphrases(t, &answer);
        for (line, reason) in parsed.rejected {
            report.rejected.push((format!("{t} -> {line}"), reason));
        }
        out.insert((*t).clone(), parsed.accepted);
    }
    Ok(out)
}

/// Pairs an LLM says a person cannot do at once (SINC's optional semantic check): `pair_compat`
/// asked once per pair of normalised texts, through the cache. Pairs without an answer are not
/// vetoed; the report counts them as skipped.
pub fn incompatible_pairs(
    pairs: &[(String, String)],
    prompts: &Prompts,
    llm: Option<&LlmConfig>,
    offline: bool,
    cache: Option<&mut ResponseCache>,
    report: &mut AugmentReport,
) -> Result<BTreeSet<(String, String)>, PromptError> {
    report.texts = pairs.len();
    let rendered: Vec<String> = pairs
        .iter()
        .map(|(a, b)| prompts.pair_compat(a, b))
        .collect::<Result<_, _>>()?;
    let mut out = BTreeSet::new();
    for (pair, answer) in pairs
        .iter()
        .zip(answers(&rendered, llm, offline, cache, report))
    {
        let Some(answer) = answer else { continue };
        report.answered += 1;
        let first = answer
            .trim()
            .trim_start_matches(|c: char| !c.is_alphabetic())
            .to_lowercase();
        let word: String = first.chars().take_while(|c| c.is_alphabetic()).collect();
        if word == "no" {
            out.insert(pair.clone());
        } else if word != "yes" {
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
    llm: Option<&LlmConfig>,
    offline: bool,
    mut cache: Option<&mut ResponseCache>,
    report: &mut AugmentReport,
) -> Result<BTreeMap<String, Vec<PlanStep>>, PromptError> {
    let texts: Vec<&String> = texts.iter().collect();
    report.texts = texts.len();
    let rendered: Vec<String> = texts
        .iter()
        .map(|t| prompts.task_plan(t))
        .collect::<Result<_, _>>()?;
    let first = answers(&rendered, llm, offline, cache.as_deref_mut(), report);
    let mut out = BTreeMap::new();
    let mut repairs: Vec<(usize, String)> = Vec::new();
    for (i, answer) in first.iter().enumerate() {
        let Some(answer) = answer else { continue };
        match parse_task_plan(answer) {
            Ok(steps) => {
                report.answered += 1;
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
        for ((i, _), answer) in
            repairs
                .iter()
                .zip(answers(&again, llm, offline, cache, &mut repair_report))
        {
            report.requests += repair_report.requests;
            repair_report.requests = 0;
            let result = answer
                .ok_or_else(|| "no answer to the repair request".to_string())
                .and_then(|a| parse_task_plan(&a).map_err(|e| e.to_string()));
            match result {
                Ok(steps) => {
                    report.answered += 1;
                    out.insert(texts[*i].clone(), steps);
                }
                Err(reason) => report.rejected.push((
                    texts[*i].clone(),
                    format!("invalid plan after one repair: {reason}"),
                )),
            }
        }
    }
    Ok(out)
}
