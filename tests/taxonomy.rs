//! The bundled motion-type taxonomy (LINGO Table A1) and label mapping on real BABEL labels.

use crate::common;

use std::collections::BTreeMap;

use motionforge::annotate::taxonomy::{
    MatchKind, MotionType, Taxonomy, TaxonomyError, TypeMap, TypeMapConfig, TypeRule,
};

/// Every motion name LINGO's Table A1 shows, with the group we read it in. `play` appears twice in
/// the table; the drums/piano row is `play instrument` here (see schemas/motion-types.md).
const TABLE_A1: &[(&str, &str)] = &[
    ("walk forward", "locomotion"),
    ("walk back", "locomotion"),
    ("walk front left", "locomotion"),
    ("walk front right", "locomotion"),
    ("turn left", "turning"),
    ("turn right", "turning"),
    ("stand up", "standing up"),
    ("get up", "standing up"),
    ("take photo", "hand-held object interaction"),
    ("turn on", "hand-held object interaction"),
    ("write", "hand-held object interaction"),
    ("type on", "hand-held object interaction"),
    ("read", "hand-held object interaction"),
    ("play", "hand-held object interaction"),
    ("drink", "hand-held object interaction"),
    ("eat", "hand-held object interaction"),
    ("talk on", "hand-held object interaction"),
    ("listen to music", "hand-held object interaction"),
    ("brush teeth", "hand-held object interaction"),
    ("toss", "hand-held object interaction"),
    ("swing", "hand-held object interaction"),
    ("wave", "hand-held object interaction"),
    ("pick up", "pick up / put down"),
    ("put down", "pick up / put down"),
    ("stand still", "stationary"),
    ("maintain lie", "stationary"),
    ("maintain sit", "stationary"),
    ("maintain bend", "stationary"),
    ("maintain kneel", "stationary"),
    ("maintain squat", "stationary"),
    ("bend forward", "in-place"),
    ("straighten up", "in-place"),
    ("kneel down", "in-place"),
    ("squat down", "in-place"),
    ("crawl", "in-place"),
    ("sit down", "static scene-object interaction"),
    ("lie down", "static scene-object interaction"),
    ("punch", "static scene-object interaction"),
    ("kick", "static scene-object interaction"),
    ("wash", "static scene-object interaction"),
    ("take shower", "static scene-object interaction"),
    ("rotate", "static scene-object interaction"),
    ("play instrument", "static scene-object interaction"),
    ("type", "static scene-object interaction"),
];

fn bundled() -> Taxonomy {
    Taxonomy::bundled().unwrap_or_else(|e| panic!("{e}"))
}

fn names<'a>(types: impl Iterator<Item = &'a MotionType>) -> Vec<&'a str> {
    types.map(|t| t.name.as_str()).collect()
}

fn extra(name: &str, group: &str, mirror: Option<&str>) -> MotionType {
    MotionType {
        name: name.into(),
        group: group.into(),
        locomotion: group == "locomotion",
        hand_goal: false,
        scene_dependent: false,
        mirror: mirror.map(str::to_string),
        description: String::new(),
    }
}

#[test]
fn bundled_taxonomy_has_the_documented_counts() {
    let t = bundled();
    let groups: Vec<&str> = t.groups().map(|g| g.name.as_str()).collect();
    assert_eq!(
        groups,
        [
            "locomotion",
            "turning",
            "standing up",
            "hand-held object interaction",
            "pick up / put down",
            "stationary",
            "in-place",
            "static scene-object interaction",
        ]
    );
    // 44 types: the table's 46 rows less the repeated pick up / put down rows (schemas/motion-types.md).
    assert_eq!(t.types().count(), 44);
    let per_group: Vec<usize> = groups.iter().map(|g| t.types_in(g).count()).collect();
    assert_eq!(per_group, [4, 2, 2, 14, 2, 6, 5, 9]);
    assert_eq!(
        t.group("pick up / put down")
            .map(|g| g.description.as_str()),
        Some("Pick up and put down hand-held objects.")
    );
}

#[test]
fn every_table_a1_name_is_present_in_its_group() {
    let t = bundled();
    for (name, group) in TABLE_A1 {
        let ty = t.get(name).unwrap_or_else(|| panic!("`{name}` missing"));
        assert_eq!(ty.group, *group, "{name}");
        assert!(!ty.description.is_empty(), "{name} has no description");
    }
    assert_eq!(
        names(t.types()),
        TABLE_A1.iter().map(|(n, _)| *n).collect::<Vec<_>>(),
        "the file holds exactly the table's types, in table order"
    );
    assert_eq!(t.objects("play"), ["game", "guitar"]);
    assert_eq!(t.objects("play instrument"), ["drums", "piano"]);
}

#[test]
fn flags_follow_lingo() {
    let t = bundled();
    let flagged = |f: fn(&MotionType) -> bool| names(t.types().filter(|x| f(x)));
    assert_eq!(
        flagged(|x| x.locomotion),
        [
            "walk forward",
            "walk back",
            "walk front left",
            "walk front right"
        ]
    );
    assert_eq!(flagged(|x| x.hand_goal), ["pick up", "put down"]);
    assert_eq!(
        flagged(|x| x.scene_dependent),
        [
            "walk forward",
            "walk back",
            "walk front left",
            "walk front right",
            "write",
            "type on",
            "sit down",
            "lie down",
            "punch",
            "kick",
            "wash",
            "take shower",
            "rotate",
            "play instrument",
            "type",
        ]
    );
    let get = |n: &str| t.get(n).unwrap_or_else(|| panic!("{n}"));
    assert!(get("walk forward").locomotion && !get("walk forward").hand_goal);
    assert!(get("pick up").hand_goal && !get("pick up").locomotion);
    assert!(!get("drink").scene_dependent && !get("talk on").scene_dependent);
    assert!(get("sit down").scene_dependent && !get("sit down").locomotion);
    assert!(!get("turn on").hand_goal && !get("take photo").hand_goal);
}

#[test]
fn mirrors_are_mutual() {
    let t = bundled();
    assert_eq!(t.mirror_of("turn left"), Some("turn right"));
    assert_eq!(t.mirror_of("turn right"), Some("turn left"));
    assert_eq!(t.mirror_of("walk front left"), Some("walk front right"));
    assert_eq!(t.mirror_of("Walk_Front-Right"), Some("walk front left"));
    assert_eq!(t.mirror_of("walk forward"), Some("walk forward"));
    assert_eq!(t.mirror_of("fly"), None);
    let sided = names(t.types().filter(|x| x.mirror.is_some()));
    assert_eq!(
        sided,
        [
            "walk front left",
            "walk front right",
            "turn left",
            "turn right"
        ]
    );
    for ty in t.types() {
        let there = t
            .mirror_of(&ty.name)
            .unwrap_or_else(|| panic!("{}", ty.name));
        assert_eq!(t.mirror_of(there), Some(ty.name.as_str()), "{}", ty.name);
    }
}

#[test]
fn extra_types_are_added_and_duplicates_refused() {
    let t = bundled()
        .with_extra(vec![
            extra("side step left", "locomotion", Some("side step right")),
            extra("side step right", "locomotion", Some("side step left")),
        ])
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(t.types().count(), 46);
    assert!(t.get("side step left").is_some_and(|x| x.locomotion));
    assert_eq!(t.mirror_of("side step left"), Some("side step right"));
    assert_eq!(t.types_in("locomotion").count(), 6);

    let err = bundled()
        .with_extra(vec![extra("walk forward", "locomotion", None)])
        .expect_err("duplicate");
    assert!(
        matches!(&err, TaxonomyError::DuplicateType { name, .. } if name == "walk forward"),
        "{err}"
    );
    let err = bundled()
        .with_extra(vec![extra("hop", "jumping", None)])
        .expect_err("unknown group");
    assert!(err.to_string().contains("hop") && err.to_string().contains("jumping"));
}

/// Labels of clean_labels.txt the config below maps (computed once, then pinned).
const MAPPED: usize = 30;
/// Mapped labels per type.
const PER_TYPE: &[(&str, usize)] = &[
    ("bend forward", 4),
    ("eat", 2),
    ("pick up", 9),
    ("put down", 1),
    ("stand up", 1),
    ("swing", 3),
    ("turn left", 3),
    ("turn right", 2),
    ("walk back", 2),
    ("walk forward", 2),
    ("walk front left", 1),
];
/// Mapped labels by how they were reached.
const KINDS: &[(&str, usize)] = &[("alias", 3), ("name", 6), ("rule", 21)];

/// The mapping config used on the real labels: only rules whose every match means the type.
fn babel_config() -> TypeMapConfig {
    let rule = |pattern: &str, ty: &str| TypeRule {
        pattern: pattern.into(),
        r#type: ty.into(),
    };
    TypeMapConfig {
        aliases: BTreeMap::from([
            ("bend over".into(), "bend forward".into()),
            ("golf swing".into(), "swing".into()),
            ("put glass on bar".into(), "put down".into()),
        ]),
        rules: vec![
            rule(r"^walk(s|ing)? forwards?$", "walk forward"),
            rule(r"^walk(s|ing)? (backwards?|back)$", "walk back"),
            rule(
                r"^walk(s|ing)? diagonally forwards? left$",
                "walk front left",
            ),
            rule(
                r"^walk(s|ing)? diagonally forwards? right$",
                "walk front right",
            ),
            rule(r"^turn(s|ing)? (to (the )?)?left$", "turn left"),
            rule(r"^turn(s|ing)? (to (the )?)?right$", "turn right"),
            rule(r"^sit(s|ting)?( down)?$", "sit down"),
            rule(
                r"^stand(s|ing)? up( from (the |a )?(chair|seat|bench))?$",
                "stand up",
            ),
            rule(
                r"^pick(s|ing)? up( (the |an? )?(object|item|phone|glass|something))?( (from|off) (the )?(surface|ground|floor))?( with (the )?(left|right) hand)?$",
                "pick up",
            ),
            rule(
                r"^pick(s|ing)? (something|it|the object) up( with (the )?(left|right) hand)?$",
                "pick up",
            ),
            rule(r"^bend(s|ing)? (over )?forwards?$", "bend forward"),
            rule(r"^swing(s|ing)? (the |a )?(golf )?club$", "swing"),
            rule(r"^eat(s|ing)?\b", "eat"),
        ],
        ..TypeMapConfig::default()
    }
}

fn babel_labels() -> Vec<String> {
    let path = common::shared_data().join("sinc/clean_labels.txt");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(str::to_string)
        .collect()
}

#[test]
fn maps_real_babel_labels_without_guessing() {
    let labels = babel_labels();
    assert_eq!(labels.len(), 762);
    let map = TypeMap::new(bundled(), &babel_config()).unwrap_or_else(|e| panic!("{e}"));
    let report = map.report(labels.iter().map(String::as_str));

    assert_eq!(report.mapped_count(), MAPPED);
    assert_eq!(report.unmapped.len(), 762 - MAPPED);
    let per_type: Vec<(&str, usize)> = report
        .mapped
        .iter()
        .map(|(k, v)| (k.as_str(), v.len()))
        .collect();
    assert_eq!(per_type, PER_TYPE);

    let mut kinds = BTreeMap::new();
    for label in &labels {
        if let Some((_, kind)) = map.map_with_kind(label) {
            let k = match kind {
                MatchKind::Name => "name",
                MatchKind::Alias => "alias",
                MatchKind::Rule(_) => "rule",
            };
            *kinds.entry(k).or_insert(0usize) += 1;
        }
    }
    assert_eq!(kinds, KINDS.iter().copied().collect());

    // Unmapped labels are kept as they are, not folded into the nearest type.
    for label in [
        "walk forward to the left",
        "walk in circles",
        "turn around",
        "turn around left",
        "sit on the chair",
        "pick up something and drop it",
        "kick ball",
        "throw ball",
        "run forward",
        "side step left",
    ] {
        assert!(
            report.unmapped.iter().any(|l| l == label),
            "`{label}` should stay unmapped"
        );
        assert!(map.map(label).is_none(), "{label}");
    }
    assert!(
        report.mapped.values().flatten().count() + report.unmapped.len() == labels.len(),
        "every label is reported exactly once"
    );
}

#[test]
fn extra_types_catch_dataset_specific_labels() {
    let mut config = babel_config();
    config.extra = vec![
        extra("side step left", "locomotion", Some("side step right")),
        extra("side step right", "locomotion", Some("side step left")),
    ];
    config.rules.push(TypeRule {
        pattern: r"^side step (to (the )?)?left$".into(),
        r#type: "side step left".into(),
    });
    config.rules.push(TypeRule {
        pattern: r"^side step (to (the )?)?right$".into(),
        r#type: "side step right".into(),
    });
    let map = TypeMap::new(bundled(), &config).unwrap_or_else(|e| panic!("{e}"));
    let labels = babel_labels();
    let report = map.report(labels.iter().map(String::as_str));
    assert_eq!(
        report.mapped.get("side step left").map(Vec::as_slice),
        Some(
            &[
                "side step left".to_string(),
                "side step to the left".to_string(),
                "side step to left".to_string()
            ][..]
        )
    );
    assert_eq!(
        report.mapped.get("side step right").map(Vec::len),
        Some(3),
        "{:?}",
        report.mapped.get("side step right")
    );
    assert_eq!(
        map.taxonomy().mirror_of("side step right"),
        Some("side step left")
    );
}

#[test]
fn config_errors_name_the_offending_entry() {
    let mut config = babel_config();
    config
        .aliases
        .insert("hop on one foot".into(), "hop".into());
    let err = TypeMap::new(bundled(), &config).expect_err("alias to an unknown type");
    assert!(
        matches!(&err, TaxonomyError::BadAlias { alias, target, .. } if alias == "hop on one foot" && target == "hop"),
        "{err}"
    );

    let mut config = babel_config();
    config.rules.insert(
        2,
        TypeRule {
            pattern: r"^walk (left|right".into(),
            r#type: "walk front left".into(),
        },
    );
    let err = TypeMap::new(bundled(), &config).expect_err("bad regex");
    assert!(
        matches!(&err, TaxonomyError::BadRule { index: 2, pattern, .. } if pattern == r"^walk (left|right"),
        "{err}"
    );
    assert!(err.to_string().contains("rule 2"), "{err}");

    let mut config = babel_config();
    config.rules.push(TypeRule {
        pattern: "^jog$".into(),
        r#type: "jog".into(),
    });
    let err = TypeMap::new(bundled(), &config).expect_err("rule to an unknown type");
    assert!(err.to_string().contains("jog"), "{err}");
}

#[test]
fn taxonomy_file_errors_name_the_offending_entry() {
    let base = r#"
[[groups]]
name = "turning"

[[types]]
name = "turn left"
group = "turning"

[[types]]
name = "turn right"
group = "turning"
"#;
    let dup = base.replace("\"turn right\"", "\"turn left\"");
    let err = Taxonomy::from_toml(&dup, "dup.toml").expect_err("duplicate name");
    assert!(
        matches!(&err, TaxonomyError::DuplicateType { file, name } if file == "dup.toml" && name == "turn left"),
        "{err}"
    );

    let unknown = base.replace(
        "name = \"turn right\"\ngroup = \"turning\"",
        "name = \"turn right\"\ngroup = \"spinning\"",
    );
    let err = Taxonomy::from_toml(&unknown, "group.toml").expect_err("unknown group");
    assert!(
        matches!(&err, TaxonomyError::UnknownGroup { type_name, group, .. } if type_name == "turn right" && group == "spinning"),
        "{err}"
    );

    let one_sided = base.replace(
        "name = \"turn left\"\ngroup = \"turning\"",
        "name = \"turn left\"\ngroup = \"turning\"\nmirror = \"turn right\"",
    );
    let err = Taxonomy::from_toml(&one_sided, "mirror.toml").expect_err("one-sided mirror");
    assert!(
        matches!(&err, TaxonomyError::BadMirror { type_name, mirror, .. } if type_name == "turn left" && mirror == "turn right"),
        "{err}"
    );

    let flag_typo = base.replace(
        "group = \"turning\"\n\n",
        "group = \"turning\"\nlocomtion = true\n\n",
    );
    let err = Taxonomy::from_toml(&flag_typo, "typo.toml").expect_err("misspelt flag");
    assert!(err.to_string().contains("locomtion"), "{err}");
}
