//! The evaluation's tables: one CSV row per tracer, method, setting and frame; a Markdown report
//! per frame with its chart, the Pareto front of time against FLIP, and the derived lines (the
//! fastest setting within FLIP 0.01, the cost of watertightness, the cost of bit-exactness).

use super::{Variant, intersect_name, offset_name};
use crate::bench::{field, significant};
use crate::output::{self, Kind};
use render_metrics::{HitErrors, ImageErrors, ShadingShifts};
use render_spec::Settings;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The FLIP mean a setting must stay within to count as "as good as the reference" for the
/// derived line "the fastest setting within FLIP 0.01".
pub const FLIP_GOOD: f64 = 0.01;

/// One measured setting.
#[derive(Clone, Debug)]
pub struct Row {
    pub scene: String,
    pub triangles: u64,
    pub camera: String,
    pub width: u32,
    pub height: u32,
    pub mode: String,
    /// `cpu` or `vk`.
    pub tracer: String,
    pub gpu: bool,
    pub device: String,
    pub method: String,
    /// [`Variant::label`].
    pub setting: String,
    pub variant: Variant,
    pub indirections: u32,
    pub median_ms: f64,
    pub min_ms: f64,
    pub rays: [u64; 3],
    pub image: ImageErrors,
    pub hits: HitErrors,
    pub shifts: ShadingShifts,
    /// Exact acne: of the one-sample render's shadow, secondary, AO and diffuse rays, those the
    /// triangle they leave from meets (render_spec::SelfHits, both tracers' `--self-hits`).
    pub self_hits: u64,
}

/// The mode as `bench` names it (`cast`, `whitted2`, `ao8`, `diffuse`).
pub fn mode_name(s: &Settings) -> String {
    crate::bench::BenchMode { mode: s.mode, lights: s.lights.len() }.name()
}

/// The CSV columns, in order.
pub const CSV_HEADER: &str = "scene,triangles,camera,width,height,mode,tracer,device,method,setting,intersect,offset,\
                              spp,cutoff,indirections,exact,median_ms,min_ms,primary,shadow,secondary,flip_mean,\
                              flip_p99,psnr_db,off_1_share,off_8_share,hit_rays,hit_disagree,hit_ties,leaks,\
                              darker,lighter,self_hits";

impl Row {
    /// The frame this row belongs to: its chart and its section of the report.
    pub fn frame(&self) -> (String, String, u32, u32, String) {
        (self.scene.clone(), self.camera.clone(), self.width, self.height, self.mode.clone())
    }

    /// The marker's series: tracer and method.
    pub fn series(&self) -> String {
        format!("{} {}", self.tracer, self.method)
    }

    pub fn csv(&self) -> String {
        let a = &self.variant.accuracy;
        let [p, s, r] = self.rays;
        let (i, h, sh) = (&self.image, &self.hits, &self.shifts);
        format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.5},{:.5},{p},{s},{r},{:.6},{:.6},{:.3},{:.6},{:.6},{},{},{},{},{},{},{}",
            field(&self.scene),
            self.triangles,
            field(&self.camera),
            self.width,
            self.height,
            self.mode,
            self.tracer,
            field(&self.device),
            self.method,
            self.setting,
            intersect_name(a.intersect),
            offset_name(a.offset),
            a.spp,
            a.cutoff,
            self.indirections,
            self.variant.exact,
            self.median_ms,
            self.min_ms,
            i.flip_mean,
            i.flip_p99,
            i.psnr,
            i.off_1,
            i.off_8,
            h.rays,
            h.disagree,
            h.ties,
            h.leaks,
            sh.darker,
            sh.lighter,
            self.self_hits,
        )
    }
}

/// The rows not beaten by another in both time and FLIP mean (no other is at least as fast and
/// at least as accurate, and better in one), fastest first.
pub fn pareto<'a>(rows: &[&'a Row]) -> Vec<&'a Row> {
    let beats = |q: &Row, p: &Row| {
        q.median_ms <= p.median_ms
            && q.image.flip_mean <= p.image.flip_mean
            && (q.median_ms < p.median_ms || q.image.flip_mean < p.image.flip_mean)
    };
    let mut front: Vec<&Row> = rows.iter().copied().filter(|p| !rows.iter().any(|q| beats(q, p))).collect();
    front.sort_by(|a, b| a.median_ms.total_cmp(&b.median_ms));
    front
}

/// The derived lines of one frame, per tracer and method.
pub fn derived_lines(rows: &[&Row]) -> Vec<String> {
    let mut lines = Vec::new();
    let mut series: Vec<String> = rows.iter().map(|r| r.series()).collect();
    series.dedup();
    series.sort();
    series.dedup();
    for s in &series {
        let of: Vec<&Row> = rows.iter().copied().filter(|r| r.series() == *s).collect();
        let find = |label: &str| of.iter().copied().find(|r| r.setting == label);
        let good = of
            .iter()
            .copied()
            .filter(|r| r.image.flip_mean <= FLIP_GOOD)
            .min_by(|a, b| a.median_ms.total_cmp(&b.median_ms));
        lines.push(match good {
            Some(r) => format!(
                "{s}: the fastest setting within FLIP {FLIP_GOOD} is **{}** ({} ms, FLIP {}).",
                r.setting,
                significant(r.median_ms),
                significant(r.image.flip_mean)
            ),
            None => format!("{s}: no setting comes within FLIP {FLIP_GOOD} of the reference."),
        });
        if let (Some(w), Some(m)) = (find("default"), find("mt")) {
            lines.push(format!(
                "{s}: the cost of watertightness: the watertight test takes {}x the time of Möller-Trumbore \
                 ({} ms against {} ms); leaks {} against {}, hits that differ from the reference {} against {}.",
                significant(w.median_ms / m.median_ms),
                significant(w.median_ms),
                significant(m.median_ms),
                w.hits.leaks,
                m.hits.leaks,
                w.hits.disagree,
                m.hits.disagree
            ));
        }
        if let (Some(d), Some(e)) = (find("default"), find("exact")) {
            lines.push(format!(
                "{s}: the cost of bit-exactness: --exact takes {}x the time ({} ms against {} ms); FLIP {} against {}.",
                significant(e.median_ms / d.median_ms),
                significant(e.median_ms),
                significant(d.median_ms),
                significant(e.image.flip_mean),
                significant(d.image.flip_mean)
            ));
        }
    }
    lines
}

fn table_row(r: &Row) -> String {
    let (i, h, s) = (&r.image, &r.hits, &r.shifts);
    let pct = |x: f64| format!("{}%", significant(100.0 * x));
    format!(
        "| {} {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
        r.tracer,
        r.method,
        r.setting,
        significant(r.median_ms),
        significant(i.flip_mean),
        significant(i.flip_p99),
        if i.psnr.is_finite() { significant(i.psnr) } else { "inf".to_owned() },
        pct(i.off_1),
        pct(i.off_8),
        h.disagree,
        h.ties,
        h.leaks,
        s.darker,
        s.lighter,
        r.self_hits
    )
}

/// The chart's file name (without extension) of a frame.
pub fn chart_stem(frame: &(String, String, u32, u32, String)) -> String {
    let (scene, camera, w, h, mode) = frame;
    let clean =
        |s: &str| s.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect::<String>();
    format!("{}-{}-{w}x{h}-{}", clean(scene), clean(camera), clean(mode))
}

/// The frames of `rows` in the order they were measured.
pub fn frames(rows: &[Row]) -> Vec<(String, String, u32, u32, String)> {
    let mut out: Vec<(String, String, u32, u32, String)> = Vec::new();
    for r in rows {
        let f = r.frame();
        if !out.contains(&f) {
            out.push(f);
        }
    }
    out
}

/// The Markdown report.
pub fn markdown(preface: &[String], rows: &[Row]) -> String {
    let mut s = String::from("# Speed against accuracy\n\n");
    for p in preface {
        let _ = writeln!(s, "- {p}");
    }
    s.push_str(
        "\nColumns: median milliseconds per frame; FLIP mean and 99th percentile against the reference image; \
         PSNR; pixels off by more than 1/255 and 8/255; of the primary rays (one sample per pixel, the setting's \
         test and offset): hits on another triangle than the reference's (ties at shared edges apart), ties, leaks \
         (past a surface the reference ray stops at); of the pixels whose hit agrees, those darker (acne, as the \
         image shows it) and lighter (missed shadows) by more than 8/255; self-hits: exact acne, the rays of \
         that render (shadow, secondary, AO, diffuse) that the triangle they leave from meets.\n",
    );
    for f in frames(rows) {
        let group: Vec<&Row> = rows.iter().filter(|r| r.frame() == f).collect();
        let (scene, camera, w, h, mode) = &f;
        let stem = chart_stem(&f);
        let _ = writeln!(s, "\n## {scene}, {camera}, {w}x{h}, {mode}\n");
        let _ = writeln!(s, "![FLIP against time: {scene}]({stem}.svg)\n");
        for line in derived_lines(&group) {
            let _ = writeln!(s, "- {line}");
        }
        s.push_str("\nPareto front (no other setting is both faster and closer to the reference):\n\n");
        s.push_str("| tracer, method | setting | ms | FLIP mean |\n|---|---|--:|--:|\n");
        for r in pareto(&group) {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} |",
                r.series(),
                r.setting,
                significant(r.median_ms),
                significant(r.image.flip_mean)
            );
        }
        s.push_str(
            "\n| tracer, method | setting | ms | FLIP mean | FLIP p99 | PSNR dB | >1/255 | >8/255 | hits differ | ties | \
             leaks | darker | lighter | self-hits |\n|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|\n",
        );
        for r in &group {
            let _ = writeln!(s, "{}", table_row(r));
        }
    }
    s
}

/// Writes eval.csv, eval.md and a chart per frame (SVG and PNG) into `dir`. Returns the files.
pub fn write(dir: &Path, preface: &[String], rows: &[Row]) -> Result<Vec<PathBuf>, String> {
    let csv_path = dir.join("eval.csv");
    let md_path = dir.join("eval.md");
    let checked = output::check(&[("eval.csv", &csv_path, Kind::Table), ("eval.md", &md_path, Kind::Markdown)], &[])
        .map_err(|e| e.to_string())?;
    let mut text = String::from(CSV_HEADER);
    text.push('\n');
    for r in rows {
        text.push_str(&r.csv());
        text.push('\n');
    }
    output::write_text(&checked[0], &text).map_err(|e| e.to_string())?;
    output::write_text(&checked[1], &markdown(preface, rows)).map_err(|e| e.to_string())?;
    let mut written = vec![csv_path, md_path];
    for f in frames(rows) {
        let group: Vec<&Row> = rows.iter().filter(|r| r.frame() == f).collect();
        let stem = chart_stem(&f);
        let (scene, camera, w, h, mode) = &f;
        let title = format!("{scene}, {camera}, {w}x{h}, {mode}");
        written.extend(super::chart::draw(dir, &stem, &title, &group, &pareto(&group))?);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(tracer: &str, setting: &str, ms: f64, flip: f64, leaks: u64) -> Row {
        Row {
            scene: "bunny".into(),
            triangles: 1,
            camera: "medium".into(),
            width: 4,
            height: 3,
            mode: "whitted1".into(),
            tracer: tracer.into(),
            gpu: tracer == "vk",
            device: "d, e".into(),
            method: "m".into(),
            setting: setting.into(),
            variant: Variant::default(),
            indirections: 1,
            median_ms: ms,
            min_ms: ms,
            rays: [12, 0, 0],
            image: ImageErrors { flip_mean: flip, flip_p99: flip, psnr: 30.0, off_1: 0.5, off_8: 0.25 },
            hits: HitErrors { rays: 12, leaks, ..Default::default() },
            shifts: ShadingShifts::default(),
            self_hits: 0,
        }
    }

    #[test]
    fn the_pareto_front_keeps_only_unbeaten_settings_fastest_first() {
        let rows = [
            row("cpu", "default", 10.0, 0.05, 0),
            row("cpu", "spp 4", 40.0, 0.01, 0),
            row("cpu", "mt", 9.0, 0.05, 2),
            row("cpu", "offset 1e-2", 12.0, 0.06, 0),
            row("vk", "spp 16", 2.0, 0.004, 0),
        ];
        let refs: Vec<&Row> = rows.iter().collect();
        let front: Vec<&str> = pareto(&refs).iter().map(|r| r.setting.as_str()).collect();
        assert_eq!(front, ["spp 16"]);
        let cpu: Vec<&Row> = rows[..4].iter().collect();
        let front: Vec<&str> = pareto(&cpu).iter().map(|r| r.setting.as_str()).collect();
        assert_eq!(front, ["mt", "spp 4"]);
    }

    #[test]
    fn derived_lines_name_the_fastest_good_setting_and_the_costs() {
        let rows =
            [row("cpu", "default", 10.0, 0.05, 0), row("cpu", "spp 4", 40.0, 0.008, 0), row("cpu", "mt", 8.0, 0.05, 3)];
        let refs: Vec<&Row> = rows.iter().collect();
        let lines = derived_lines(&refs);
        assert!(lines[0].contains("**spp 4** (40.0 ms, FLIP 0.00800)"), "{lines:?}");
        assert!(
            lines[1].contains("1.25x the time of Möller-Trumbore") && lines[1].contains("leaks 0 against 3"),
            "{lines:?}"
        );
        let csv = rows[0].csv();
        assert_eq!(csv.split(',').count(), CSV_HEADER.split(',').count(), "{csv}");
        assert!(csv.contains("d; e"));
    }
}
