//! Stick-figure previews of clips from the shards alone: an animated GIF and a PNG filmstrip.
//!
//! Each clip is drawn in its own canonical frame (origin at the first frame's pelvis on the
//! ground, facing +y), seen by a fixed orthographic camera in front of the character, raised by
//! [`ELEVATION_DEGREES`]: the camera lies in the character's sagittal plane, so a mirrored clip's
//! drawing is exactly the reflection of its original's. Bones take the colour of their body part
//! (left side cool, right side warm), over a ground grid of half-metre squares, under the clip's
//! caption and whole id (wrapped, never cut: a title band as tall as the longest title needs).
//! Several clips side by side (a clip and its mirror) share one scale; a synthetic pair and its
//! sources may each fit their own panel ([`PanelScale::Own`]), with a one-metre bar to compare.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use glam::{DQuat, DVec3};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

use super::{ClipFrames, DatasetError, SkeletonEntry};
use motionforge_core::motion::{BodyPart, Motion, Role};

/// The camera's height above the character, as an angle below the horizontal.
pub const ELEVATION_DEGREES: f64 = 20.0;
/// Ground grid spacing, metres.
const GRID_M: f64 = 0.5;
/// Caption text size and line height (pixels).
const CAPTION_PX: u32 = 13;
const CAPTION_LINE: u32 = 16;
/// Clip id text size and line height (pixels): large enough to read a synthetic id.
const ID_PX: u32 = 12;
const ID_LINE: u32 = 15;
/// Pixels above and below a title's lines.
const TITLE_PAD: u32 = 5;
/// Most lines of a caption (then it is cut with an ellipsis); an id always shows whole.
const MAX_CAPTION_LINES: usize = 4;
/// Most lines of an id: ids from shards made elsewhere may be arbitrarily long.
const MAX_ID_LINES: usize = 12;
const FONT: &str = "sans-serif";
const FONT_BYTES: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");

/// How previews are drawn.
#[derive(Debug, Clone, PartialEq)]
pub struct PreviewOptions {
    /// Frames per second of the GIF: the clip is resampled to this rate. Multiples of 100 / n
    /// (20, 25, 50) keep GIF's centisecond delays exact.
    pub fps: f64,
    /// Width and height of one clip's drawing area in pixels, title excluded.
    pub size: u32,
    /// Frames in the filmstrip, evenly spaced over the clip.
    pub strip_frames: usize,
    /// Draw the GIF's frames too (a filmstrip alone needs none).
    pub animate: bool,
}

impl Default for PreviewOptions {
    fn default() -> Self {
        PreviewOptions {
            fps: 20.0,
            size: 280,
            strip_frames: 8,
            animate: true,
        }
    }
}

/// How the panels of one preview are scaled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PanelScale {
    /// One scale for every panel, so side-by-side clips (a clip and its mirror) compare.
    #[default]
    Shared,
    /// Each panel fits its own clip (a synthetic pair beside sources that walk far), with a
    /// one-metre bar in each.
    Own,
}

/// One clip to draw: its frames and its skeleton.
#[derive(Debug, Clone)]
pub struct Panel<'a> {
    /// The row's metadata and frames.
    pub frames: &'a ClipFrames,
    /// Its `skeletons.json` entry.
    pub skeleton: &'a SkeletonEntry,
}

fn render_err(e: impl std::fmt::Display) -> DatasetError {
    DatasetError::Render {
        message: e.to_string(),
    }
}

/// The first frame's canonical frame of a row: the root-motion joint dropped to the ground, and
/// the turn about z that makes the character face +y (from the hips, else shoulders).
fn canonical(frames: &ClipFrames, entry: &SkeletonEntry) -> (DVec3, DQuat) {
    let p = |j: usize| match frames.positions.get(j * 3..j * 3 + 3) {
        Some(v) => DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2])),
        None => DVec3::ZERO,
    };
    let root = entry
        .joints
        .iter()
        .position(|j| j.name == entry.root)
        .unwrap_or(0);
    let origin = p(root) * DVec3::new(1.0, 1.0, 0.0);
    let side = |role: Role, left: bool| {
        entry.joints.iter().position(|j| {
            j.role == Some(role)
                && j.part.is_some_and(|p| match p {
                    BodyPart::LeftArm | BodyPart::LeftLeg => left,
                    BodyPart::RightArm | BodyPart::RightLeg => !left,
                    BodyPart::Global | BodyPart::Torso => false,
                })
        })
    };
    let mut rotation = DQuat::IDENTITY;
    for role in [Role::Hip, Role::Shoulder] {
        if let (Some(a), Some(b)) = (side(role, true), side(role, false)) {
            let right = (p(b) - p(a)) * DVec3::new(1.0, 1.0, 0.0);
            if right.length() > 1e-6 {
                let forward = DVec3::Z.cross(right.normalize());
                // Angle from the facing to +y, about z.
                let angle = forward.x.atan2(forward.y);
                rotation = DQuat::from_rotation_z(angle);
                break;
            }
        }
    }
    (origin, rotation)
}

/// Every frame's joint positions in the row's first-frame canonical frame (`frames × joints × 3`,
/// metres, x right, y forward, z up): what the service's player draws.
pub fn canonical_positions(frames: &ClipFrames, entry: &SkeletonEntry) -> Vec<f32> {
    let (origin, rotation) = canonical(frames, entry);
    frames
        .positions
        .chunks_exact(3)
        .flat_map(|v| {
            let c =
                rotation * (DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2])) - origin);
            [c.x as f32, c.y as f32, c.z as f32]
        })
        .collect()
}

/// The camera's image-plane coordinates (metres: u to the image's right, v up) and depth of a
/// canonical-frame point.
fn project(p: DVec3) -> ([f64; 2], f64) {
    let (s, c) = ELEVATION_DEGREES.to_radians().sin_cos();
    // Looking along -y from in front and above: the character's right (+x) is the image's left.
    ([-p.x, -p.y * s + p.z * c], -p.y * c - p.z * s)
}

/// Every frame's projected joints of a row at its own rate (`frames × joints` points, image-plane
/// metres): what the preview draws, before the pixel mapping.
pub fn projected_points(frames: &ClipFrames, entry: &SkeletonEntry) -> Vec<[f64; 2]> {
    projected(frames, entry)
        .into_iter()
        .map(|(p, _)| p)
        .collect()
}

fn projected(frames: &ClipFrames, entry: &SkeletonEntry) -> Vec<([f64; 2], f64)> {
    let (origin, rotation) = canonical(frames, entry);
    frames
        .positions
        .chunks_exact(3)
        .map(|v| {
            let world = DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
            project(rotation * (world - origin))
        })
        .collect()
}

/// RGB of a body part; left side cool, right side warm.
fn part_colour(part: Option<BodyPart>) -> RGBColor {
    match part {
        Some(BodyPart::LeftArm) => RGBColor(31, 90, 220),
        Some(BodyPart::LeftLeg) => RGBColor(0, 160, 170),
        Some(BodyPart::RightArm) => RGBColor(220, 40, 40),
        Some(BodyPart::RightLeg) => RGBColor(240, 140, 0),
        Some(BodyPart::Torso) => RGBColor(60, 60, 60),
        Some(BodyPart::Global) | None => RGBColor(120, 120, 120),
    }
}

const GRID: RGBColor = RGBColor(200, 200, 200);
const INK: RGBColor = RGBColor(0, 0, 0);
const GOAL: RGBColor = RGBColor(150, 0, 170);
const ID_INK: RGBColor = RGBColor(60, 60, 60);

fn ensure_font() -> Result<(), DatasetError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| register_font(FONT, FontStyle::Normal, FONT_BYTES).is_ok());
    if ok {
        Ok(())
    } else {
        Err(render_err("the bundled font cannot be registered"))
    }
}

/// One panel ready to draw: its points resampled to the preview rate, its pixel mapping and
/// its ground grid.
struct Scene<'a> {
    panel: &'a Panel<'a>,
    /// `frames × joints` projected points and depths at the preview rate.
    points: Vec<([f64; 2], f64)>,
    joints: usize,
    /// Image-plane centre of the panel's extent.
    centre: [f64; 2],
    /// Ground extent in canonical x and y (min, max), grid-aligned.
    ground: ([f64; 2], [f64; 2]),
    /// Joints at or below the root-motion joint: bones hang from these only, so a static file
    /// root left at the world origin (Bandai Namco's `joint_Root`) draws no line to the pelvis.
    body: Vec<bool>,
}

impl Scene<'_> {
    fn frames(&self) -> usize {
        self.points.len() / self.joints.max(1)
    }
}

fn scene<'a>(panel: &'a Panel<'a>, fps: f64) -> Scene<'a> {
    let info = &panel.frames.info;
    let joints = info.joints;
    let all = projected(panel.frames, panel.skeleton);
    let mut points = Vec::new();
    for (lo, hi, t) in Motion::resample_points(info.frames, info.fps, fps) {
        for j in 0..joints {
            let (a, da) = all[lo * joints + j];
            let (b, db) = all[hi * joints + j];
            points.push((
                [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t],
                da + (db - da) * t,
            ));
        }
    }
    // The ground under every frame's joints, in canonical coordinates (for the grid).
    let (origin, rotation) = canonical(panel.frames, panel.skeleton);
    let mut gx = [f64::INFINITY, f64::NEG_INFINITY];
    let mut gy = gx;
    for v in panel.frames.positions.chunks_exact(3) {
        let c = rotation * (DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2])) - origin);
        gx = [gx[0].min(c.x), gx[1].max(c.x)];
        gy = [gy[0].min(c.y), gy[1].max(c.y)];
    }
    let snap = |r: [f64; 2]| {
        [
            ((r[0] - GRID_M) / GRID_M).floor() * GRID_M,
            ((r[1] + GRID_M) / GRID_M).ceil() * GRID_M,
        ]
    };
    let ground = (snap(gx), snap(gy));
    let (lo, hi) = extent(&points, ground);
    let root = panel
        .skeleton
        .joints
        .iter()
        .position(|j| j.name == panel.skeleton.root)
        .unwrap_or(0);
    let mut body = vec![false; panel.skeleton.joints.len()];
    for (j, joint) in panel.skeleton.joints.iter().enumerate() {
        body[j] = j == root || joint.parent.is_some_and(|p| p < j && body[p]);
    }
    Scene {
        panel,
        points,
        joints,
        body,
        centre: [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0],
        ground,
    }
}

/// The image-plane box holding every point and the ground grid.
fn extent(points: &[([f64; 2], f64)], ground: ([f64; 2], [f64; 2])) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    let mut add = |p: [f64; 2]| {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    };
    for (p, _) in points {
        add(*p);
    }
    for x in ground.0 {
        for y in ground.1 {
            add(project(DVec3::new(x, y, 0.0)).0);
        }
    }
    (lo, hi)
}

/// Pixels per image-plane metre so that every scene fits its square panel (one scale for all, so
/// side-by-side clips compare).
fn common_scale(scenes: &[Scene], size: u32) -> f64 {
    let mut span: f64 = 0.5;
    for s in scenes {
        let (lo, hi) = extent(&s.points, s.ground);
        span = span.max(hi[0] - lo[0]).max(hi[1] - lo[1]);
    }
    f64::from(size) * 0.92 / span
}

/// Width in pixels of `text` in the bundled font at `font_px` (an estimate if it cannot be
/// measured).
fn text_width(text: &str, font_px: u32) -> u32 {
    (FONT, font_px)
        .into_font()
        .box_size(text)
        .map(|(w, _)| w)
        .unwrap_or_else(|_| (text.chars().count() as f64 * f64::from(font_px) * 0.6) as u32)
}

/// `text` in lines at most `px` pixels wide at `font_px`: broken after the last of `breaks` that
/// fits in the line's second half, else where the line is full; at most `max_lines`, the last
/// ending in `…` if the text goes on.
fn wrap(text: &str, px: u32, font_px: u32, breaks: &[char], max_lines: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut rest: Vec<char> = text.chars().collect();
    while !rest.is_empty() {
        let fits = |n: usize| text_width(&rest[..n].iter().collect::<String>(), font_px) <= px;
        let mut n = rest.len();
        if !fits(n) {
            // The longest start that fits (at least one character), by bisection.
            let (mut lo, mut hi) = (1, rest.len());
            while lo + 1 < hi {
                let mid = (lo + hi) / 2;
                if fits(mid) { lo = mid } else { hi = mid }
            }
            n = lo;
            if let Some(at) = rest[..n].iter().rposition(|c| breaks.contains(c))
                && at + 1 > n / 2
            {
                n = at + 1;
            }
        }
        if lines.len() + 1 == max_lines && n < rest.len() {
            let mut last: String = rest[..n.saturating_sub(1).max(1)].iter().collect();
            last.push('…');
            lines.push(last);
            break;
        }
        let line: String = rest[..n].iter().collect();
        lines.push(line.trim_end().to_string());
        rest.drain(..n);
        while rest.first() == Some(&' ') {
            rest.remove(0);
        }
    }
    lines
}

/// A panel's title as drawn: the caption's lines (`mirrored: ` first for a mirrored copy) and
/// the whole clip id's lines, in `px` pixels.
pub fn title_lines(info: &super::ClipInfo, px: u32) -> (Vec<String>, Vec<String>) {
    let caption = if info.mirrored {
        format!("mirrored: {}", info.text)
    } else {
        info.text.clone()
    };
    (
        wrap(&caption, px, CAPTION_PX, &[' '], MAX_CAPTION_LINES),
        wrap(
            &info.clip_id,
            px,
            ID_PX,
            &['/', ':', '+', '_', '-'],
            MAX_ID_LINES,
        ),
    )
}

/// Height of the band that holds `titles`.
fn title_band(titles: &[(Vec<String>, Vec<String>)]) -> u32 {
    titles
        .iter()
        .map(|(c, i)| c.len() as u32 * CAPTION_LINE + i.len() as u32 * ID_LINE)
        .max()
        .unwrap_or(0)
        + 2 * TITLE_PAD
}

type Draw = Result<(), Box<dyn std::error::Error + Send + Sync>>;

/// A panel's title and where it goes: its lines and the height of the band above the panel.
struct TitleBand<'t> {
    lines: &'t (Vec<String>, Vec<String>),
    height: u32,
}

/// A panel's cell as drawn: a `size`-pixel square at `origin` of an `image`-sized RGB buffer,
/// showing `scene` at `scale` pixels per image-plane metre.
struct Cell<'s> {
    image: ImageSize,
    origin: (i32, i32),
    scene: &'s Scene<'s>,
    scale: f64,
    size: u32,
}

type Area<'b> = DrawingArea<BitMapBackend<'b>, plotters::coord::Shift>;

impl Cell<'_> {
    /// Image-plane metres to pixels of this cell.
    fn px(&self, p: [f64; 2]) -> (i32, i32) {
        let c = self.scene.centre;
        let half = f64::from(self.size) / 2.0;
        (
            self.origin.0 + (half + (p[0] - c[0]) * self.scale).round() as i32,
            self.origin.1 + (half - (p[1] - c[1]) * self.scale).round() as i32,
        )
    }

    /// Runs `draw` on the cell's drawing area over `buf`, then presents it.
    fn paint(&self, buf: &mut [u8], draw: impl FnOnce(&Area) -> Draw) -> Draw {
        let root = BitMapBackend::with_buffer(buf, self.image).into_drawing_area();
        draw(&root)?;
        root.present()?;
        Ok(())
    }

    /// Draws the title and ground grid, and a one-metre bar when `bar`.
    fn background(&self, buf: &mut [u8], title: &TitleBand, bar: bool) -> Draw {
        let (x0, y0) = self.origin;
        self.paint(buf, |root| {
            self.ground(root, grid_steps(self.scene.ground.0))?;
            let caption = TextStyle::from((FONT, CAPTION_PX).into_font()).color(&INK);
            let id = TextStyle::from((FONT, ID_PX).into_font()).color(&ID_INK);
            let mut y = y0 - title.height as i32 + TITLE_PAD as i32;
            for line in &title.lines.0 {
                root.draw(&Text::new(line.as_str(), (x0 + 4, y), caption.clone()))?;
                y += CAPTION_LINE as i32;
            }
            for line in &title.lines.1 {
                root.draw(&Text::new(line.as_str(), (x0 + 4, y), id.clone()))?;
                y += ID_LINE as i32;
            }
            if bar {
                // One metre of the image plane at this panel's scale, bottom left.
                let length = self.scale.round().clamp(1.0, f64::from(self.size) - 16.0) as i32;
                let at = y0 + self.size as i32 - 10;
                root.draw(&PathElement::new(
                    vec![(x0 + 8, at), (x0 + 8 + length, at)],
                    INK.stroke_width(2),
                ))?;
                root.draw(&Text::new(
                    "1 m",
                    (x0 + 10 + length, at - 7),
                    TextStyle::from((FONT, ID_PX).into_font()).color(&ID_INK),
                ))?;
            }
            Ok(())
        })
    }

    /// The ground grid of a filmstrip cell after the first, with the cell's time.
    fn grid(&self, buf: &mut [u8]) -> Draw {
        let gx = self.scene.ground.0;
        self.paint(buf, |root| self.ground(root, [gx[0], gx[1]].into_iter()))
    }

    /// Draws frame `f` of the scene: bones far to near, coloured by the child joint's part, and
    /// the pelvis goal as a marker when the row has one.
    fn pose(&self, buf: &mut [u8], f: usize) -> Draw {
        let scene = self.scene;
        let n = scene.joints;
        let pose = &scene.points[f * n..(f + 1) * n];
        let joints = &scene.panel.skeleton.joints;
        let body = &scene.body;
        let mut bones: Vec<(f64, usize, usize)> = joints
            .iter()
            .enumerate()
            .filter_map(|(j, joint)| joint.parent.filter(|p| *p < n && j < n).map(|p| (j, p)))
            .filter(|(_, p)| body.get(*p).copied().unwrap_or(false))
            .map(|(j, p)| ((pose[j].1 + pose[p].1) / 2.0, j, p))
            .collect();
        bones.sort_by(|a, b| b.0.total_cmp(&a.0));
        let width = (f64::from(self.size) / 90.0).round().max(2.0) as u32;
        self.paint(buf, |root| {
            for (_, j, p) in bones {
                let colour = part_colour(joints[j].part);
                root.draw(&PathElement::new(
                    vec![self.px(pose[p].0), self.px(pose[j].0)],
                    colour.stroke_width(width),
                ))?;
            }
            if let Some(g) = &scene.panel.frames.info.goal_pelvis
                && g.len() >= 2
            {
                let at = self.px(project(DVec3::new(f64::from(g[0]), f64::from(g[1]), 0.0)).0);
                root.draw(&Cross::new(at, 5, GOAL.stroke_width(2)))?;
            }
            Ok(())
        })
    }

    /// The ground's lines along y at `xs`, then across it at every [`grid_steps`] of its depth.
    fn ground(&self, root: &Area, xs: impl Iterator<Item = f64>) -> Draw {
        let (gx, gy) = self.scene.ground;
        for x in xs {
            let a = self.px(project(DVec3::new(x, gy[0], 0.0)).0);
            let b = self.px(project(DVec3::new(x, gy[1], 0.0)).0);
            root.draw(&PathElement::new(vec![a, b], GRID))?;
        }
        for y in grid_steps(gy) {
            let a = self.px(project(DVec3::new(gx[0], y, 0.0)).0);
            let b = self.px(project(DVec3::new(gx[1], y, 0.0)).0);
            root.draw(&PathElement::new(vec![a, b], GRID))?;
        }
        Ok(())
    }
}

/// A rendered preview: the GIF's frames (RGB), the filmstrip (RGB), their sizes.
pub struct Preview {
    /// Width and height of a GIF frame.
    pub frame_size: (u32, u32),
    /// RGB frames at the preview rate.
    pub frames: Vec<Vec<u8>>,
    /// Frames per second.
    pub fps: f64,
    /// Width and height of the filmstrip.
    pub strip_size: (u32, u32),
    /// The filmstrip, RGB.
    pub strip: Vec<u8>,
}

/// Renders `panels` side by side (the GIF) and one filmstrip row per panel, on one scale.
pub fn render(panels: &[Panel], options: &PreviewOptions) -> Result<Preview, DatasetError> {
    render_scaled(panels, options, PanelScale::Shared)
}

/// [`render`], with the panels scaled as `scaling` says.
pub fn render_scaled(
    panels: &[Panel],
    options: &PreviewOptions,
    scaling: PanelScale,
) -> Result<Preview, DatasetError> {
    ensure_font()?;
    check_panels(panels, options)?;
    let size = options.size.clamp(64, 2048);
    let scenes: Vec<Scene> = panels.iter().map(|p| scene(p, options.fps)).collect();
    let scales: Vec<f64> = match scaling {
        PanelScale::Shared => vec![common_scale(&scenes, size); scenes.len()],
        PanelScale::Own => scenes
            .iter()
            .map(|s| common_scale(std::slice::from_ref(s), size))
            .collect(),
    };
    let view = PanelView {
        scenes: &scenes,
        scales: &scales,
        size,
        bar: scaling == PanelScale::Own,
    };
    let (frame_size, frames) = view.animation(options.animate)?;
    let (strip_size, strip) = view.filmstrip(options.strip_frames)?;
    Ok(Preview {
        frame_size,
        frames,
        fps: options.fps,
        strip_size,
        strip,
    })
}

/// Something to draw, at a preview rate in range, each skeleton with the row's joints.
fn check_panels(panels: &[Panel], options: &PreviewOptions) -> Result<(), DatasetError> {
    if panels.is_empty() {
        return Err(render_err("nothing to draw"));
    }
    if !(options.fps.is_finite() && options.fps > 0.0 && options.fps <= 100.0) {
        return Err(render_err(format!(
            "preview rate {} fps: expected more than 0 and at most 100",
            options.fps
        )));
    }
    for p in panels {
        if p.skeleton.joints.len() != p.frames.info.joints {
            return Err(render_err(format!(
                "clip `{}`: skeleton `{}` has {} joints, the row {}",
                p.frames.info.clip_id,
                p.frames.info.skeleton,
                p.skeleton.joints.len(),
                p.frames.info.joints
            )));
        }
    }
    Ok(())
}

/// Width and height of an image, in pixels.
type ImageSize = (u32, u32);

/// The panels' scenes as drawn: each on its scale, in square cells of `size` pixels; `bar`
/// draws each panel's own scale bar.
struct PanelView<'a> {
    scenes: &'a [Scene<'a>],
    scales: &'a [f64],
    size: u32,
    bar: bool,
}

impl PanelView<'_> {
    /// The GIF: the panels side by side under their titles, a frame per preview frame (none
    /// unless `animate`); a shorter clip holds its last pose. Returns the frame size and frames.
    fn animation(&self, animate: bool) -> Result<(ImageSize, Vec<Vec<u8>>), DatasetError> {
        let (scenes, scales, size) = (self.scenes, self.scales, self.size);
        let count = scenes.iter().map(Scene::frames).max().unwrap_or(0);
        // The GIF's titles fit their panel; the filmstrip's, the whole row.
        let titles: Vec<_> = scenes
            .iter()
            .map(|s| title_lines(&s.panel.frames.info, size - 8))
            .collect();
        let band = title_band(&titles);
        let (w, h) = (size * scenes.len() as u32, size + band);
        let cells: Vec<_> = scenes
            .iter()
            .enumerate()
            .map(|(k, scene)| Cell {
                image: (w, h),
                origin: ((size * k as u32) as i32, band as i32),
                scene,
                scale: scales[k],
                size,
            })
            .collect();
        let mut background = vec![255u8; (w * h * 3) as usize];
        for (cell, lines) in cells.iter().zip(&titles) {
            let title = TitleBand {
                lines,
                height: band,
            };
            cell.background(&mut background, &title, self.bar)
                .map_err(render_err)?;
        }
        let count = if animate { count } else { 0 };
        let mut frames = Vec::with_capacity(count);
        for f in 0..count {
            let mut buf = background.clone();
            for cell in &cells {
                // A shorter clip holds its last pose.
                let at = f.min(cell.scene.frames().saturating_sub(1));
                cell.pose(&mut buf, at).map_err(render_err)?;
            }
            frames.push(buf);
        }
        Ok(((w, h), frames))
    }

    /// The filmstrip: one row per panel, `strip_frames` poses each (1 to 32) evenly over the
    /// clip, on the same scale. Returns its size and pixels.
    fn filmstrip(&self, strip_frames: usize) -> Result<(ImageSize, Vec<u8>), DatasetError> {
        let (scenes, size, bar) = (self.scenes, self.size, self.bar);
        let cells = strip_frames.clamp(1, 32) as u32;
        let row_titles: Vec<_> = scenes
            .iter()
            .map(|s| title_lines(&s.panel.frames.info, size * cells - 8))
            .collect();
        let row_band = title_band(&row_titles);
        let (sw, sh) = (size * cells, (size + row_band) * scenes.len() as u32);
        let mut strip = vec![255u8; (sw * sh * 3) as usize];
        for (r, s) in scenes.iter().enumerate() {
            let scale = self.scales[r];
            let y0 = (r as u32 * (size + row_band) + row_band) as i32;
            let title = TitleBand {
                lines: &row_titles[r],
                height: row_band,
            };
            let n = s.frames();
            for c in 0..cells {
                let at = if cells == 1 || n < 2 {
                    0
                } else {
                    (c as usize * (n - 1)) / (cells as usize - 1)
                };
                let cell = Cell {
                    image: (sw, sh),
                    origin: ((c * size) as i32, y0),
                    scene: s,
                    scale,
                    size,
                };
                if c == 0 {
                    cell.background(&mut strip, &title, bar)
                } else {
                    cell.grid(&mut strip)
                }
                .map_err(render_err)?;
                cell.pose(&mut strip, at).map_err(render_err)?;
            }
        }
        Ok(((sw, sh), strip))
    }
}

/// Every [`GRID_M`] from the start of the ground range `r` to about its end.
fn grid_steps(r: [f64; 2]) -> impl Iterator<Item = f64> {
    let n = ((r[1] - r[0]) / GRID_M).round().clamp(0.0, 400.0) as usize;
    (0..=n).map(move |i| r[0] + i as f64 * GRID_M)
}

/// The GIF palette: the drawing's own colours first, then a 6×6×6 cube and a grey ramp for
/// the text's antialiasing; and the nearest entry of every 15-bit colour, computed once.
fn palette() -> &'static (Vec<u8>, Vec<u8>) {
    static PALETTE: OnceLock<(Vec<u8>, Vec<u8>)> = OnceLock::new();
    PALETTE.get_or_init(|| {
        let mut colours: Vec<[u8; 3]> = vec![[255, 255, 255], [0, 0, 0]];
        for c in [
            part_colour(Some(BodyPart::LeftArm)),
            part_colour(Some(BodyPart::LeftLeg)),
            part_colour(Some(BodyPart::RightArm)),
            part_colour(Some(BodyPart::RightLeg)),
            part_colour(Some(BodyPart::Torso)),
            part_colour(None),
            GRID,
            GOAL,
            RGBColor(90, 90, 90),
        ] {
            colours.push([c.0, c.1, c.2]);
        }
        for r in 0..6u8 {
            for g in 0..6u8 {
                for b in 0..6u8 {
                    colours.push([r * 51, g * 51, b * 51]);
                }
            }
        }
        let mut grey = 8u8;
        while colours.len() < 256 {
            colours.push([grey, grey, grey]);
            grey = grey.saturating_add(9);
        }
        let flat: Vec<u8> = colours.iter().flatten().copied().collect();
        let mut nearest = vec![0u8; 1 << 15];
        for (key, slot) in nearest.iter_mut().enumerate() {
            let c = [
                ((key >> 10) & 31) as i32 * 255 / 31,
                ((key >> 5) & 31) as i32 * 255 / 31,
                (key & 31) as i32 * 255 / 31,
            ];
            let best = colours
                .iter()
                .enumerate()
                .min_by_key(|(_, p)| (0..3).map(|k| (c[k] - i32::from(p[k])).pow(2)).sum::<i32>())
                .map(|(i, _)| i)
                .unwrap_or(0);
            *slot = best as u8;
        }
        (flat, nearest)
    })
}

fn indexed(rgb: &[u8]) -> Vec<u8> {
    let (_, nearest) = palette();
    rgb.chunks_exact(3)
        .map(|p| {
            let key = (usize::from(p[0] >> 3) << 10)
                | (usize::from(p[1] >> 3) << 5)
                | usize::from(p[2] >> 3);
            nearest[key]
        })
        .collect()
}

impl Preview {
    /// The animated GIF (looping), one frame per preview frame.
    pub fn gif(&self) -> Result<Vec<u8>, DatasetError> {
        let (w, h) = self.frame_size;
        let (w16, h16) = (
            u16::try_from(w).map_err(render_err)?,
            u16::try_from(h).map_err(render_err)?,
        );
        let mut out = Vec::new();
        {
            let mut encoder =
                gif::Encoder::new(&mut out, w16, h16, &palette().0).map_err(render_err)?;
            encoder
                .set_repeat(gif::Repeat::Infinite)
                .map_err(render_err)?;
            let delay = (100.0 / self.fps).round() as u16;
            for rgb in &self.frames {
                let frame = gif::Frame {
                    width: w16,
                    height: h16,
                    delay,
                    buffer: std::borrow::Cow::Owned(indexed(rgb)),
                    ..gif::Frame::default()
                };
                encoder.write_frame(&frame).map_err(render_err)?;
            }
        }
        Ok(out)
    }

    /// The filmstrip as PNG.
    pub fn png(&self) -> Result<Vec<u8>, DatasetError> {
        png_bytes(&self.strip, self.strip_size)
    }
}

/// RGB pixels as PNG bytes.
pub fn png_bytes(rgb: &[u8], (w, h): (u32, u32)) -> Result<Vec<u8>, DatasetError> {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, w, h);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(render_err)?;
        writer.write_image_data(rgb).map_err(render_err)?;
    }
    Ok(out)
}

/// A file name for a clip id: `/`, `:` and `+` become `_`; a name longer than 120 characters is
/// cut and given the id's SHA-256 prefix, so synthetic ids stay unique and within file-name
/// limits.
pub fn file_stem(clip_id: &str) -> String {
    // Control characters and a leading dot too: the stem is always a plain, visible file name
    // inside the output folder, whatever a shard from elsewhere calls its clips.
    let mut stem: String = clip_id
        .chars()
        .map(|c| {
            if matches!(c, '/' | ':' | '+' | '\\') || c.is_control() {
                '_'
            } else {
                c
            }
        })
        .collect();
    if stem.is_empty() || stem.starts_with('.') {
        stem.insert(0, '_');
    }
    if stem.chars().count() <= 120 {
        stem
    } else {
        let cut: String = stem.chars().take(100).collect();
        let sha = motionforge_core::base::sha256_hex(clip_id.as_bytes());
        format!("{cut}-{}", &sha[..12])
    }
}

/// Writes `<dir>/<stem>.gif` and `<dir>/<stem>.png` atomically; returns their paths.
pub fn write_preview(
    preview: &Preview,
    dir: &Path,
    stem: &str,
) -> Result<[PathBuf; 2], DatasetError> {
    std::fs::create_dir_all(dir).map_err(|source| DatasetError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let gif = dir.join(format!("{stem}.gif"));
    let png = dir.join(format!("{stem}.png"));
    for (path, bytes) in [(&gif, preview.gif()?), (&png, preview.png()?)] {
        motionforge_core::base::write_atomic(path, &bytes).map_err(|e| DatasetError::Io {
            path: path.clone(),
            source: std::io::Error::other(e.to_string()),
        })?;
    }
    Ok([gif, png])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_clip_id_from_elsewhere_always_gives_a_plain_visible_file_name() {
        for id in [
            "..",
            ".",
            "",
            "../../etc/passwd",
            "/tmp/x",
            "a\0b",
            "a\nb",
            ".hidden",
        ] {
            let stem = file_stem(id);
            assert!(
                motionforge_core::base::guard::is_plain_name(&stem),
                "{id:?} -> {stem:?}"
            );
            assert!(!stem.starts_with('.'), "{id:?} -> {stem:?}");
        }
        // Real ids keep their spelling.
        assert_eq!(file_stem("cmu/01_01:0-120"), "cmu_01_01_0-120".to_string());
    }
}
