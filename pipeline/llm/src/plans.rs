//! LINGO task plans (a JSON list of steps) from LLM answers, and the mirroring of paraphrases
//! (their checks are in `paraphrase.rs`).
//! Invalid answers are explained, never patched up: the caller retries with [`repair_message`]
//! or rejects the item with the reason.

use serde::{Deserialize, Serialize};

use motionforge_language::text::mirror_text;

/// A step's category in LINGO's planner.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepCategory {
    /// Moving the person's position.
    Locomotion,
    /// Grabbing or touching an object.
    Grasp,
    /// Operating an object or appliance.
    Interaction,
}

/// One step of a task plan.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PlanStep {
    /// What to do.
    pub step: String,
    /// 1-based position.
    pub step_id: u32,
    /// Category.
    pub category: StepCategory,
}

/// Why a task-plan answer is not valid.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// No JSON array in the answer.
    #[error("the answer contains no JSON array of steps")]
    NoArray,
    /// The array does not parse.
    #[error("the JSON array does not parse: {0}")]
    Json(#[source] serde_json::Error),
    /// The array is empty.
    #[error("the plan has no steps")]
    Empty,
    /// A step is malformed.
    #[error("step {index}: {problem}")]
    Step {
        /// 1-based position in the array.
        index: usize,
        /// What is wrong with it.
        problem: StepProblem,
    },
}

/// What is wrong with one step of a task plan.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StepProblem {
    /// The step is not a JSON object.
    #[error("expected an object {{step, step_id, category}}")]
    NotAnObject,
    /// `step` is missing, not a string, or blank.
    #[error("`step` must be a non-empty string")]
    NoText,
    /// `step_id` is missing or not a whole number.
    #[error("`step_id` must be a whole number")]
    NoId,
    /// `step_id` is not the step's position.
    #[error("`step_id` is {id}, expected {index} (ids run 1..n in order)")]
    OutOfOrder {
        /// The id given.
        id: u64,
        /// The step's 1-based position.
        index: usize,
    },
    /// `category` is missing or not one of the three.
    #[error("`category` is {}, expected locomotion, grasp or interaction", .found.as_ref().map_or_else(|| "missing".to_string(), |c| format!("`{c}`")))]
    Category {
        /// The category given (trimmed, lowercased), `None` when missing.
        found: Option<String>,
    },
}

/// The text between the first `[` and the last `]`: models wrap JSON in prose or code fences.
fn json_array(answer: &str) -> Option<&str> {
    let start = answer.find('[')?;
    let end = answer.rfind(']')?;
    (end > start).then(|| &answer[start..=end])
}

/// Parses and validates a task plan: a JSON array of `{step, step_id, category}` with ids 1..n in
/// order, categories `locomotion`, `grasp` or `interaction`, and non-empty steps.
pub fn parse_task_plan(answer: &str) -> Result<Vec<PlanStep>, PlanError> {
    let array = json_array(answer).ok_or(PlanError::NoArray)?;
    let values: Vec<serde_json::Value> = serde_json::from_str(array).map_err(PlanError::Json)?;
    if values.is_empty() {
        return Err(PlanError::Empty);
    }
    let mut steps = Vec::with_capacity(values.len());
    for (i, v) in values.iter().enumerate() {
        let index = i + 1;
        let bad = |problem: StepProblem| PlanError::Step { index, problem };
        let obj = v.as_object().ok_or_else(|| bad(StepProblem::NotAnObject))?;
        let step = obj
            .get("step")
            .and_then(|s| s.as_str())
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .ok_or_else(|| bad(StepProblem::NoText))?;
        let id = obj
            .get("step_id")
            .and_then(|s| {
                s.as_u64()
                    .or_else(|| s.as_str().and_then(|t| t.trim().parse().ok()))
            })
            .ok_or_else(|| bad(StepProblem::NoId))?;
        if id != index as u64 {
            return Err(bad(StepProblem::OutOfOrder { id, index }));
        }
        let category = match obj
            .get("category")
            .and_then(|c| c.as_str())
            .map(|c| c.trim().to_ascii_lowercase())
        {
            Some(c) if c == "locomotion" => StepCategory::Locomotion,
            Some(c) if c == "grasp" => StepCategory::Grasp,
            Some(c) if c == "interaction" => StepCategory::Interaction,
            found => return Err(bad(StepProblem::Category { found })),
        };
        steps.push(PlanStep {
            step: step.to_string(),
            step_id: index as u32,
            category,
        });
    }
    Ok(steps)
}

/// The follow-up message asking the model to fix an invalid plan.
pub fn repair_message(error: &PlanError) -> String {
    format!(
        "Your answer was not valid: {error}. Answer again with only the JSON array \
         [{{\"step\": ..., \"step_id\": 1, \"category\": ...}}, ...], step ids 1..n in order, \
         each category one of locomotion, grasp, interaction; no other text."
    )
}

/// Paraphrases of a mirrored clip: each mirrored like its text.
pub fn mirror_paraphrases(paraphrases: &[String]) -> Vec<String> {
    paraphrases.iter().map(|p| mirror_text(p)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lingo_example_plan_parses() {
        let answer = r#"Sure! ```json
[ {"step": "walk to the sofa", "step_id": 1, "category": "locomotion"}, {"step": "sit down on the sofa", "step_id": 2, "category": "locomotion"},
  {"step": "pick up remote with left hand", "step_id": 3, "category": "grasp"}, {"step": "turn on TV with left hand", "step_id": 4, "category": "interaction"},
  {"step": "watch TV", "step_id": 5, "category": "interaction"} ]
```"#;
        let plan = parse_task_plan(answer).unwrap();
        assert_eq!(plan.len(), 5);
        assert_eq!(plan[2].category, StepCategory::Grasp);
    }

    #[test]
    fn invalid_plans_say_why() {
        let e = |s: &str| parse_task_plan(s).unwrap_err().to_string();
        assert!(e("no json here").contains("no JSON array"));
        assert!(e("[]").contains("no steps"));
        assert!(
            e(r#"[{"step": "walk", "step_id": 2, "category": "locomotion"}]"#)
                .contains("expected 1")
        );
        assert!(e(r#"[{"step": "walk", "step_id": 1, "category": "dance"}]"#).contains("`dance`"));
        assert!(e(r#"[{"step": " ", "step_id": 1, "category": "grasp"}]"#).contains("non-empty"));
        assert!(
            e(r#"[{"step": "walk", "step_id": 1, "category": "grasp"},]"#)
                .contains("does not parse")
        );
        assert!(repair_message(&PlanError::Empty).contains("only the JSON array"));
    }

    #[test]
    fn mirrored_paraphrases_swap_sides() {
        assert_eq!(
            mirror_paraphrases(&[
                "Wave using the left hand.".to_string(),
                "raise the left hand and wave it".to_string()
            ]),
            vec![
                "Wave using the right hand.",
                "raise the right hand and wave it"
            ]
        );
    }
}
