mod common;

use std::path::PathBuf;

use common::*;
use glam::DVec3;
use motionforge::motion::canonical::dataset_positions;
use motionforge::motion::{BodyPart, Profile, ProfileSpec, Role};
use motionforge::quality::{plausibility, segment_distance};
use rayon::prelude::*;

fn all_files() -> Vec<(PathBuf, &'static str)> {
    let mut v: Vec<(PathBuf, &'static str)> = Vec::new();
    for d in ["bandai-namco-1/data", "bandai-namco-2-subset/data"] {
        for f in bvh_files(&shared_data().join(d)) {
            v.push((f, "bandai-namco"));
        }
    }
    v.push((shared_data().join("cmu/01_01.bvh"), "cmu"));
    v
}

fn q(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

fn role_of(profile: &Profile, part: BodyPart, role: Role) -> Vec<usize> {
    profile
        .joints_with_role(role)
        .filter(|&j| profile.part_of[j] == Some(part))
        .collect()
}

#[test]
fn explore() {
    let rows: Vec<(String, Vec<f64>)> = all_files()
        .par_iter()
        .map(|(path, prof)| {
            let bvh = load(path);
            let profile = ProfileSpec::bundled(prof)
                .unwrap()
                .bind(&bvh.skeleton)
                .unwrap();
            let pos = dataset_positions(&bvh.motion, &profile);
            let n = bvh.motion.num_joints();
            let frames = bvh.motion.num_frames();
            let p = plausibility(&pos, n, bvh.motion.fps, &profile);
            let body: Vec<usize> = (0..n).filter(|&j| profile.roles[j] != Role::Root).collect();
            let feet: Vec<usize> = [Role::Ankle, Role::Toe]
                .iter()
                .flat_map(|&r| profile.joints_with_role(r))
                .collect();
            let toes: Vec<usize> = profile.joints_with_role(Role::Toe).collect();
            let min_toe = (0..frames)
                .flat_map(|f| toes.iter().map(move |&j| (f, j)))
                .map(|(f, j)| pos[f * n + j].z)
                .fold(f64::INFINITY, f64::min);
            let pelvis = profile.root;
            let (mut la_max, mut la_mean, mut lb_max, mut lb_mean, mut dcom) =
                (0.0f64, 0.0, 0.0f64, 0.0, 0.0);
            for f in 0..frames {
                let fr = &pos[f * n..(f + 1) * n];
                let com = body.iter().map(|&j| fr[j]).sum::<DVec3>() / body.len() as f64;
                let v = com - fr[pelvis];
                dcom += v.length() / frames as f64;
                let a = v.angle_between(DVec3::Z).to_degrees();
                la_max = la_max.max(a);
                la_mean += a / frames as f64;
                let sup = feet.iter().map(|&j| fr[j]).sum::<DVec3>() / feet.len() as f64;
                let b = (com - sup).angle_between(DVec3::Z).to_degrees();
                lb_max = lb_max.max(b);
                lb_mean += b / frames as f64;
            }
            // pair-class minima without exclusions
            let la = role_of(&profile, BodyPart::LeftArm, Role::Collar)[0];
            let ls = role_of(&profile, BodyPart::LeftArm, Role::Shoulder)[0];
            let ra = role_of(&profile, BodyPart::RightArm, Role::Collar)[0];
            let rs = role_of(&profile, BodyPart::RightArm, Role::Shoulder)[0];
            let lh = role_of(&profile, BodyPart::LeftLeg, Role::Hip)[0];
            let lk = role_of(&profile, BodyPart::LeftLeg, Role::Knee)[0];
            let rh = role_of(&profile, BodyPart::RightLeg, Role::Hip)[0];
            let rk = role_of(&profile, BodyPart::RightLeg, Role::Knee)[0];
            let mut spine: Vec<usize> = vec![pelvis];
            for r in [Role::Spine, Role::Neck, Role::Head] {
                spine.extend(role_of(&profile, BodyPart::Torso, r));
            }
            let (mut cc, mut cs, mut tt, mut ts) = (9.0f64, 9.0f64, 9.0f64, 9.0f64);
            for f in 0..frames {
                let x = |j: usize| pos[f * n + j];
                cc = cc.min(segment_distance(x(la), x(ls), x(ra), x(rs)));
                tt = tt.min(segment_distance(x(lh), x(lk), x(rh), x(rk)));
                for w in spine.windows(2) {
                    for (a, b) in [(la, ls), (ra, rs)] {
                        cs = cs.min(segment_distance(x(a), x(b), x(w[0]), x(w[1])));
                    }
                    for (a, b) in [(lh, lk), (rh, rk)] {
                        ts = ts.min(segment_distance(x(a), x(b), x(w[0]), x(w[1])));
                    }
                }
            }
            let name = path.file_stem().unwrap().to_string_lossy().to_string();
            (
                format!(
                    "{name} skate {:.3} max {:.2} contact {:.2} pen {:.3} self {:.3}@{} {:?} mintoe {:.3} leanA {:.1}/{:.1} dcom {:.3} leanB {:.1}/{:.1} cc {:.3} cs {:.3} tt {:.3} ts {:.3}",
                    p.foot_skate,
                    p.foot_skate_max,
                    p.contact_fraction,
                    p.ground_penetration,
                    p.self_distance,
                    p.self_distance_frame,
                    p.self_distance_parts,
                    min_toe,
                    la_mean,
                    la_max,
                    dcom,
                    lb_mean,
                    lb_max,
                    cc,
                    cs,
                    tt,
                    ts
                ),
                vec![
                    p.foot_skate,
                    p.foot_skate_max,
                    p.ground_penetration,
                    p.self_distance,
                    min_toe,
                    la_max,
                    lb_max,
                    cc,
                    cs,
                    tt,
                    ts,
                ],
            )
        })
        .collect();
    for (s, _) in &rows {
        println!("{s}");
    }
    let names = [
        "skate", "skatemax", "pen", "self", "mintoe", "leanA", "leanB", "cc", "cs", "tt", "ts",
    ];
    for (i, name) in names.iter().enumerate() {
        let mut v: Vec<f64> = rows.iter().map(|r| r.1[i]).collect();
        println!(
            "{name}: min {:.3} med {:.3} p05 {:.3} p95 {:.3} max {:.3}",
            q(&mut v, 0.0),
            q(&mut v, 0.5),
            q(&mut v, 0.05),
            q(&mut v, 0.95),
            q(&mut v, 1.0)
        );
    }
}

#[test]
fn trace() {
    let name = std::env::var("TRACE").unwrap_or("walk_normal".into());
    let (path, prof) = all_files()
        .into_iter()
        .find(|(p, _)| p.to_string_lossy().contains(&name))
        .unwrap();
    let bvh = load(&path);
    let profile = ProfileSpec::bundled(prof)
        .unwrap()
        .bind(&bvh.skeleton)
        .unwrap();
    let pos = dataset_positions(&bvh.motion, &profile);
    let n = bvh.motion.num_joints();
    let fps = bvh.motion.fps;
    let a = role_of(&profile, BodyPart::LeftLeg, Role::Ankle)[0];
    let t = role_of(&profile, BodyPart::LeftLeg, Role::Toe)[0];
    let frames = bvh.motion.num_frames();
    let za: Vec<f64> = (0..frames).map(|f| pos[f * n + a].z).collect();
    let zt: Vec<f64> = (0..frames).map(|f| pos[f * n + t].z).collect();
    let la = za.iter().cloned().fold(9.0, f64::min);
    let lt = zt.iter().cloned().fold(9.0, f64::min);
    for f in 0..frames - 1 {
        let va = (pos[(f + 1) * n + a] - pos[f * n + a]) * fps;
        let vt = (pos[(f + 1) * n + t] - pos[f * n + t]) * fps;
        println!(
            "{f:4} ankle h {:.3} vh {:.2} vz {:+.2} | toe h {:.3} vh {:.2} vz {:+.2}",
            za[f] - la,
            va.truncate().length(),
            va.z,
            zt[f] - lt,
            vt.truncate().length(),
            vt.z
        );
    }
}

#[test]
fn explore_skate() {
    // per clip, per foot, per step: (h_ankle, h_toe, vh_ankle, vh_toe, vz_ankle, vz_toe)
    let clips: Vec<(String, Vec<[f64; 6]>)> = all_files()
        .par_iter()
        .map(|(path, prof)| {
            let bvh = load(path);
            let profile = ProfileSpec::bundled(prof).unwrap().bind(&bvh.skeleton).unwrap();
            let pos = dataset_positions(&bvh.motion, &profile);
            let n = bvh.motion.num_joints();
            let fps = bvh.motion.fps;
            let step = ((fps / 30.0).round() as usize).max(1);
            let dt = step as f64 / fps;
            let frames = bvh.motion.num_frames();
            let mut rows = Vec::new();
            let level = |role: Role| {
                let mut z: Vec<f64> = [BodyPart::LeftLeg, BodyPart::RightLeg]
                    .iter()
                    .flat_map(|&s| role_of(&profile, s, role))
                    .flat_map(|j| (0..frames).map(move |f| (f, j)))
                    .map(|(f, j)| pos[f * n + j].z)
                    .collect();
                q(&mut z, 0.02)
            };
            let (la, lt) = (level(Role::Ankle), level(Role::Toe));
            for side in [BodyPart::LeftLeg, BodyPart::RightLeg] {
                let a = role_of(&profile, side, Role::Ankle)[0];
                let t = role_of(&profile, side, Role::Toe)[0];
                for f in 0..frames.saturating_sub(step) {
                    let (a0, a1) = (pos[f * n + a], pos[(f + step) * n + a]);
                    let (t0, t1) = (pos[f * n + t], pos[(f + step) * n + t]);
                    rows.push([
                        a0.z.max(a1.z) - la,
                        t0.z.max(t1.z) - lt,
                        (a1 - a0).truncate().length() / dt,
                        (t1 - t0).truncate().length() / dt,
                        ((a1.z - a0.z) / dt).abs(),
                        ((t1.z - t0.z) / dt).abs(),
                    ]);
                }
            }
            (path.file_stem().unwrap().to_string_lossy().to_string(), rows)
        })
        .collect();
    let variants: Vec<(&str, Box<dyn Fn(&[f64; 6]) -> Option<f64> + Sync>)> = vec![
        ("any3", Box::new(|r: &[f64; 6]| {
            let a = (r[0] < 0.03 && r[4] < 0.3).then_some(r[2]);
            let t = (r[1] < 0.03 && r[5] < 0.3).then_some(r[3]);
            match (a, t) { (Some(x), Some(y)) => Some(x.min(y)), (x, y) => x.or(y) }
        })),
        ("both1", Box::new(|r: &[f64; 6]| (r[0] < 0.01 && r[1] < 0.01 && r[4] < 0.3 && r[5] < 0.3).then_some(r[2].min(r[3])))),
        ("both15", Box::new(|r: &[f64; 6]| (r[0] < 0.015 && r[1] < 0.015 && r[4] < 0.3 && r[5] < 0.3).then_some(r[2].min(r[3])))),
        ("both2", Box::new(|r: &[f64; 6]| (r[0] < 0.02 && r[1] < 0.02 && r[4] < 0.3 && r[5] < 0.3).then_some(r[2].min(r[3])))),
        ("both2v1", Box::new(|r: &[f64; 6]| (r[0] < 0.02 && r[1] < 0.02 && r[4] < 0.1 && r[5] < 0.1).then_some(r[2].min(r[3])))),
        ("both3", Box::new(|r: &[f64; 6]| (r[0] < 0.03 && r[1] < 0.03 && r[4] < 0.3 && r[5] < 0.3).then_some(r[2].min(r[3])))),
        ("both2max", Box::new(|r: &[f64; 6]| (r[0] < 0.02 && r[1] < 0.02 && r[4] < 0.3 && r[5] < 0.3).then_some(r[2].max(r[3])))),
    ];
    for (vname, v) in &variants {
        let mut means = Vec::new();
        let mut meds = Vec::new();
        let mut worst = (0.0, String::new());
        let mut fracs = Vec::new();
        for (name, rows) in &clips {
            let mut s: Vec<f64> = rows.iter().filter_map(|r| v(r)).collect();
            fracs.push(s.len() as f64 / rows.len() as f64);
            if s.is_empty() { means.push(0.0); meds.push(0.0); continue; }
            let m = s.iter().sum::<f64>() / s.len() as f64;
            if m > worst.0 { worst = (m, name.clone()); }
            if *vname == "both2" || *vname == "both15" { println!("{vname} {name} {m:.3} n {} frac {:.2}", s.len(), s.len() as f64 / rows.len() as f64); }
            means.push(m);
            meds.push(q(&mut s, 0.5));
        }
        println!(
            "{vname}: mean: med {:.3} p95 {:.3} max {:.3} ({}) | median: med {:.3} p95 {:.3} max {:.3} | frac min {:.2} med {:.2}",
            q(&mut means, 0.5), q(&mut means, 0.95), q(&mut means, 1.0), worst.1,
            q(&mut meds, 0.5), q(&mut meds, 0.95), q(&mut meds, 1.0),
            q(&mut fracs, 0.0), q(&mut fracs, 0.5)
        );
    }
}
