//! The CI slice of the stability sweep (issue 9, `stress --quick`): a cheap point or two of every
//! axis, every method (CPU ordered, stackless, packet; Vulkan LST, stackless, SST, SST-subgroup
//! on lavapipe), asserting that no pixel fails in silence: no wrong closest hit against the f64
//! reference, no leak, no NaN or infinite value, no wrong pixel where an image is compared, no
//! crash and no hang. A refusal (a typed error naming the limit) is allowed and printed.
//! The sweep's full range and its charts are in docs/stability.md.

mod common;

use std::sync::Arc;
use std::time::Duration;
use tools::stress::cases::{self, AXES, Extent};
use tools::stress::{METHODS, report};

/// Points known to fail in silence on every method (docs/stability.md, "Findings"), each with
/// the reason. They are run and must still fail, so that the fix is noticed and the point moves
/// into the asserted set; every other point must not fail.
const KNOWN: &[(&str, &str, &str)] = &[
    (
        "scale",
        "10^-8",
        "the self-intersection offset's absolute constants (OFFSET_ORIGIN 1/32, OFFSET_FLOAT_SCALE \
         1/65536, render-spec) move secondary-ray origins by more than the whole 1.2e-7-wide scene",
    ),
    ("scale", "10^8", "about 1% of the pixels differ in colour from the scene at scale 1; cause not yet found"),
];

#[test]
fn no_method_fails_in_silence_on_any_axis() {
    let gpu = Arc::new(common::gpu());
    let all = cases::all(Extent::Quick);
    // The sweep's demonstration of what the compiler's rebasing prevents is not a method.
    let checked: Vec<_> = all.into_iter().filter(|c| c.axis != AXES[1]).collect();
    let rows = tools::stress::sweep(checked, &METHODS, Some(gpu.clone()), Duration::from_secs(300), &|row| {
        println!("{} {} {}: {}", row.axis, row.label, row.method.name(), report::cell(&row.tally));
        if let Some(r) = &row.tally.refusal {
            println!("    refused: {r}");
        }
    });
    let mut silent = Vec::new();
    for r in &rows {
        let known = KNOWN.iter().find(|(a, l, _)| *a == r.axis && *l == r.label);
        match (r.tally.silent_failure(), known) {
            (true, None) => {
                silent.push(format!("{} {} {}: {}", r.axis, r.label, r.method.name(), report::cell(&r.tally)))
            }
            (false, Some((a, l, why))) => silent.push(format!(
                "{a} {l} {}: no longer fails ({why}): remove it from KNOWN and the findings",
                r.method.name()
            )),
            _ => {}
        }
    }
    assert!(silent.is_empty(), "failed in silence:\n{}", silent.join("\n"));
    // Every axis ran on every method.
    for axis in AXES.iter().filter(|a| **a != AXES[1]) {
        for m in METHODS {
            assert!(rows.iter().any(|r| r.axis == *axis && r.method == m), "{axis} did not run on {}", m.name());
        }
    }
    assert!(gpu.validation_messages().is_empty());
}
