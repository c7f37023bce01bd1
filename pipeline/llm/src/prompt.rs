//! Prompt templates (`prompts/*.j2`, minijinja) and the data they are filled with
//! (`prompts/*.toml`). Rendering is strict: a variable the template uses but the context lacks
//! is an error naming the template, the line and the variable.

use std::collections::BTreeMap;
use std::path::Path;

use minijinja::value::Serde;
use minijinja::{Environment, UndefinedBehavior, Value};
use serde::{Deserialize, Serialize};

/// The bundled templates and their data, compiled into the binary.
const BUNDLED: [(&str, &str); 6] = [
    (
        "part_labels.j2",
        include_str!("../../../prompts/part_labels.j2"),
    ),
    (
        "part_labels.toml",
        include_str!("../../../prompts/part_labels.toml"),
    ),
    (
        "task_plan.j2",
        include_str!("../../../prompts/task_plan.j2"),
    ),
    (
        "task_plan.toml",
        include_str!("../../../prompts/task_plan.toml"),
    ),
    (
        "paraphrase.j2",
        include_str!("../../../prompts/paraphrase.j2"),
    ),
    (
        "pair_compat.j2",
        include_str!("../../../prompts/pair_compat.j2"),
    ),
];

/// Template names, as `motionforge prompt render` takes them.
pub const TEMPLATES: [&str; 4] = ["part_labels", "task_plan", "paraphrase", "pair_compat"];

/// Why a prompt cannot be rendered.
#[derive(Debug, thiserror::Error)]
pub enum PromptError {
    /// The template is unknown.
    #[error(
        "no prompt template `{0}` (templates: part_labels, task_plan, paraphrase, pair_compat)"
    )]
    Unknown(String),
    /// A template does not parse or does not render.
    #[error("template `{template}`{}: {}", line.map(|l| format!(" line {l}")).unwrap_or_default(), template_problem(error, missing))]
    Template {
        /// Template file.
        template: String,
        /// 1-based line, where known.
        line: Option<usize>,
        /// minijinja's error. Not a `#[source]`: the message quotes its detail, and its full
        /// form would be appended by whatever prints the causes.
        error: minijinja::Error,
        /// Variables the template uses that were not given, sorted.
        missing: Vec<String>,
    },
    /// A data file does not parse.
    #[error("prompt data `{file}`: {source}")]
    Data {
        /// Data file.
        file: String,
        /// The parser's error.
        source: toml::de::Error,
    },
    /// A prompts folder cannot be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

/// SINC Table 1's prompt variants for part labels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PartPromptVariant {
    /// (a) The question only.
    FreeForm,
    /// (b) Instruction, list and question.
    List,
    /// (c) Instruction, list, four few-shot pairs and question (SINC's final prompt).
    #[default]
    ListFewShot,
}

impl PartPromptVariant {
    /// All variants, in Table 1 order.
    pub const ALL: [PartPromptVariant; 3] = [
        PartPromptVariant::FreeForm,
        PartPromptVariant::List,
        PartPromptVariant::ListFewShot,
    ];

    /// The name used in templates and configs.
    pub fn as_str(self) -> &'static str {
        match self {
            PartPromptVariant::FreeForm => "free_form",
            PartPromptVariant::List => "list",
            PartPromptVariant::ListFewShot => "list_few_shot",
        }
    }
}

/// Loaded templates and data.
#[derive(Debug)]
pub struct Prompts {
    env: Environment<'static>,
    data: BTreeMap<String, toml::Table>,
}

impl Prompts {
    /// The templates compiled into the binary.
    pub fn bundled() -> Result<Prompts, PromptError> {
        Prompts::from_files(
            BUNDLED
                .iter()
                .map(|(n, t)| (n.to_string(), t.to_string()))
                .collect(),
        )
    }

    /// The bundled templates with any file of the same name in `dir` in its place.
    pub fn with_overrides(dir: &Path) -> Result<Prompts, PromptError> {
        let mut files: BTreeMap<String, String> = BUNDLED
            .iter()
            .map(|(n, t)| (n.to_string(), t.to_string()))
            .collect();
        for name in BUNDLED.iter().map(|(n, _)| *n) {
            let path = dir.join(name);
            if path.is_file() {
                let text = std::fs::read_to_string(&path).map_err(|source| PromptError::Io {
                    path: path.clone(),
                    source,
                })?;
                files.insert(name.to_string(), text);
            }
        }
        Prompts::from_files(files)
    }

    fn from_files(files: BTreeMap<String, String>) -> Result<Prompts, PromptError> {
        let mut env = Environment::new();
        env.set_undefined_behavior(UndefinedBehavior::Strict);
        let mut data = BTreeMap::new();
        for (name, text) in &files {
            if let Some(stem) = name.strip_suffix(".toml") {
                let table: toml::Table =
                    toml::from_str(text).map_err(|source| PromptError::Data {
                        file: name.clone(),
                        source,
                    })?;
                data.insert(stem.to_string(), table);
            } else if let Some(stem) = name.strip_suffix(".j2") {
                env.add_template_owned(stem.to_string(), text.clone())
                    .map_err(|e| template_error(stem, e, Vec::new()))?;
            }
        }
        Ok(Prompts { env, data })
    }

    /// Renders `template` with `vars` plus the template's data file. Missing variables are errors.
    pub fn render(
        &self,
        template: &str,
        vars: BTreeMap<String, Value>,
    ) -> Result<String, PromptError> {
        let tmpl = self
            .env
            .get_template(template)
            .map_err(|_| PromptError::Unknown(template.to_string()))?;
        let mut context: BTreeMap<String, Value> = BTreeMap::new();
        if let Some(table) = self.data.get(template) {
            for (k, v) in table {
                context.insert(k.clone(), Value::from(Serde(v)));
            }
        }
        context.extend(vars);
        let rendered = tmpl.render(Value::from(Serde(&context))).map_err(|e| {
            let mut missing: Vec<String> = tmpl
                .undeclared_variables(false)
                .into_iter()
                .filter(|v| !context.contains_key(v))
                .collect();
            missing.sort();
            template_error(template, e, missing)
        })?;
        Ok(rendered.trim_end().to_string() + "\n")
    }

    /// SINC's body-part question for `text`.
    pub fn part_labels(
        &self,
        text: &str,
        variant: PartPromptVariant,
    ) -> Result<String, PromptError> {
        self.render(
            "part_labels",
            vars([
                ("text", Value::from(text)),
                ("variant", Value::from(variant.as_str())),
            ]),
        )
    }

    /// LINGO's task-planner prompt for `text`.
    pub fn task_plan(&self, text: &str) -> Result<String, PromptError> {
        self.render("task_plan", vars([("text", Value::from(text))]))
    }

    /// The paraphrase prompt asking for `n` alternatives.
    pub fn paraphrase(&self, text: &str, n: usize) -> Result<String, PromptError> {
        self.render(
            "paraphrase",
            vars([("text", Value::from(text)), ("n", Value::from(n))]),
        )
    }

    /// The can-both-be-done-at-once question.
    pub fn pair_compat(&self, first: &str, second: &str) -> Result<String, PromptError> {
        self.render(
            "pair_compat",
            vars([
                ("first", Value::from(first)),
                ("second", Value::from(second)),
            ]),
        )
    }
}

/// A context from name/value pairs.
pub fn vars<const N: usize>(pairs: [(&str, Value); N]) -> BTreeMap<String, Value> {
    pairs.into_iter().map(|(k, v)| (k.to_string(), v)).collect()
}

fn template_error(template: &str, error: minijinja::Error, missing: Vec<String>) -> PromptError {
    PromptError::Template {
        template: format!("{}.j2", error.name().unwrap_or(template)),
        line: error.line(),
        error,
        missing,
    }
}

/// What went wrong in a template: minijinja's detail (or the kind of error), after the variables
/// that were not given.
fn template_problem(error: &minijinja::Error, missing: &[String]) -> String {
    let detail = error
        .detail()
        .map(str::to_string)
        .unwrap_or_else(|| error.kind().to_string());
    if missing.is_empty() {
        return detail;
    }
    format!(
        "missing variable{} `{}` ({detail})",
        if missing.len() > 1 { "s" } else { "" },
        missing.join("`, `")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn part_label_prompt_is_sinc_listing_1() {
        let p = Prompts::bundled().unwrap();
        let full = p
            .part_labels("wave with the right hand", PartPromptVariant::ListFewShot)
            .unwrap();
        assert!(full.starts_with("The instructions for this task are to choose\nyour answers from the list below:\n\nleft arm\nright arm\nleft leg\nbuttocks\nwaist\nright leg\ntorso\nneck\n\nHere are some examples"));
        assert!(full.contains("Question: What are the body parts involved in the\naction of: sit down?\nAnswer: right leg\nleft leg\nbuttocks\nwaist\n\n"));
        assert!(full.ends_with("Question: What are the body parts involved in the\naction of: wave with the right hand?\n"));
        let list = p.part_labels("x", PartPromptVariant::List).unwrap();
        assert!(list.contains("neck\n\nQuestion:") && !list.contains("examples"));
        let free = p.part_labels("x", PartPromptVariant::FreeForm).unwrap();
        assert_eq!(
            free,
            "Question: What are the body parts involved in the\naction of: x?\n"
        );
    }

    #[test]
    fn missing_variables_are_named_with_template_and_line() {
        let p = Prompts::bundled().unwrap();
        let err = p
            .render("paraphrase", vars([("text", Value::from("walk"))]))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("paraphrase.j2") && err.contains("line 3") && err.contains("`n`"),
            "{err}"
        );
    }

    #[test]
    fn task_plan_prompt_carries_lingo_example_as_json() {
        let p = Prompts::bundled().unwrap();
        let t = p.task_plan("watch TV").unwrap();
        assert!(t.contains("The target action is: watch TV."));
        assert!(
            t.contains(r#""step":"pick up remote with left hand""#)
                || t.contains(r#""step": "pick up remote with left hand""#),
            "{t}"
        );
        assert!(t.contains("locomotion, grasp, interaction"));
    }
}
