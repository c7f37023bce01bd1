//! Synthetic simultaneous pairs on real Bandai captures (issue: synthetic pairs).
use crate::common;

use common::*;
use motionforge::motion::compose::{Trim, compose, part_bit};
use motionforge::motion::{BodyPart, ProfileSpec};

fn mask(parts: &[BodyPart]) -> u8 {
    parts.iter().map(|p| part_bit(*p)).sum()
}

#[test]
fn walk_plus_wave_keeps_the_walks_legs_and_root_and_the_waves_right_arm() {
    let walk = load(&bandai2("walk", 1));
    let wave = load(&bandai2("wave-right-hand", 1));
    let profile = ProfileSpec::bundled("bandai-namco")
        .unwrap()
        .bind(&walk.skeleton)
        .unwrap();
    let walk_parts = mask(&[BodyPart::Global, BodyPart::LeftLeg, BodyPart::RightLeg]);
    let wave_parts = mask(&[BodyPart::RightArm]);
    // Argument order must not matter: B is whichever has fewer parts.
    for (first, first_parts, second, second_parts, walk_is_first) in [
        (&walk.motion, walk_parts, &wave.motion, wave_parts, true),
        (&wave.motion, wave_parts, &walk.motion, walk_parts, false),
    ] {
        let c = compose(
            first,
            first_parts,
            second,
            second_parts,
            &profile,
            Trim::Start,
        );
        let frames = walk.motion.num_frames().min(wave.motion.num_frames());
        assert_eq!(c.motion.num_frames(), frames);
        let (from_walk, from_wave) = if walk_is_first {
            (c.parts_from_first, c.parts_from_second)
        } else {
            (c.parts_from_second, c.parts_from_first)
        };
        assert_eq!(from_wave, mask(&[BodyPart::RightArm]));
        assert_eq!(
            from_walk,
            mask(&[
                BodyPart::Global,
                BodyPart::Torso,
                BodyPart::LeftArm,
                BodyPart::LeftLeg,
                BodyPart::RightLeg
            ])
        );
        let sk = &walk.skeleton;
        let legs_and_root: Vec<usize> = profile
            .joints_of(BodyPart::LeftLeg)
            .chain(profile.joints_of(BodyPart::RightLeg))
            .chain(profile.joints_of(BodyPart::Global))
            .collect();
        let right_arm: Vec<usize> = profile.joints_of(BodyPart::RightArm).collect();
        assert!(!right_arm.is_empty() && legs_and_root.len() >= 9);
        for f in 0..frames {
            for &j in &legs_and_root {
                assert_eq!(
                    c.motion.rotation(f, j),
                    walk.motion.rotation(f, j),
                    "frame {f} {}",
                    sk.joints[j].name
                );
                assert_eq!(
                    c.motion.translation(f, j),
                    walk.motion.translation(f, j),
                    "frame {f} {}",
                    sk.joints[j].name
                );
            }
            for &j in &right_arm {
                assert_eq!(
                    c.motion.rotation(f, j),
                    wave.motion.rotation(f, j),
                    "frame {f} {}",
                    sk.joints[j].name
                );
            }
        }
    }
}

#[test]
fn when_b_has_a_leg_the_whole_leg_block_comes_from_b() {
    // A kick (right leg) with a two-arm action: B = kick, which involves a leg, so both legs,
    // the root rotation and the root translation come from the kick.
    let kick = load(&bandai1("kick", "normal"));
    let raise = load(&bandai2("raise-up-right-hand", 1));
    let profile = ProfileSpec::bundled("bandai-namco")
        .unwrap()
        .bind(&kick.skeleton)
        .unwrap();
    let c = compose(
        &raise.motion,
        mask(&[BodyPart::LeftArm, BodyPart::RightArm]),
        &kick.motion,
        mask(&[BodyPart::RightLeg]),
        &profile,
        Trim::Start,
    );
    let left_leg: Vec<usize> = profile
        .joints_of(BodyPart::LeftLeg)
        .chain(profile.joints_of(BodyPart::Global))
        .collect();
    for f in [0, c.motion.num_frames() / 2] {
        for &j in &left_leg {
            assert_eq!(c.motion.rotation(f, j), kick.motion.rotation(f, j));
            assert_eq!(c.motion.translation(f, j), kick.motion.translation(f, j));
        }
        for j in profile.joints_of(BodyPart::RightArm) {
            assert_eq!(c.motion.rotation(f, j), raise.motion.rotation(f, j));
        }
    }
    assert_eq!(
        c.parts_from_second,
        mask(&[BodyPart::Global, BodyPart::LeftLeg, BodyPart::RightLeg])
    );
}

#[test]
fn a_seeded_offset_trims_the_longer_motion_from_that_frame() {
    let kick = load(&bandai1("kick", "normal"));
    let wave = load(&bandai2("wave-right-hand", 1));
    let profile = ProfileSpec::bundled("bandai-namco")
        .unwrap()
        .bind(&kick.skeleton)
        .unwrap();
    assert!(kick.motion.num_frames() > wave.motion.num_frames() + 10);
    let c = compose(
        &kick.motion,
        mask(&[BodyPart::RightLeg]),
        &wave.motion,
        mask(&[BodyPart::RightArm]),
        &profile,
        Trim::At(7),
    );
    assert_eq!(c.motion.num_frames(), wave.motion.num_frames());
    assert_eq!(
        c.starts,
        [7, 0],
        "the longer kick starts at frame 7, the wave at 0"
    );
    let knee = kick.skeleton.index_of("LowerLeg_R").unwrap();
    assert_eq!(c.motion.rotation(0, knee), kick.motion.rotation(7, knee));
}
