//! The binned builder's trees against the full sweep's: with its default 16 bins (raised for
//! large nodes) it stays within 1.5 % of the sweep's SAH cost on a scene that 16 uniform bins
//! missed by 6 %: the toy car with its glass and mirrors, whose small parts lie far apart.

use bvh_build::import::{ImportOptions, load};
use bvh_format::tree::{Tree, stats};
use bvh_format::{BuildParams, Strategy};
use std::path::Path;

fn sah(positions: &[[glam::Vec3; 3]], params: &BuildParams) -> f64 {
    let t = bvh_build::build_tree(positions, params).expect("the scene builds");
    stats(Tree::child_pair(&t.nodes), params.traversal_cost, params.intersection_cost).sah_cost
}

#[test]
fn sixteen_bins_stay_within_one_and_a_half_percent_of_the_sweep_on_the_car() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/car.toml");
    let s = load(&scene, &ImportOptions::default()).expect("the car imports");
    let binned = sah(&s.positions, &BuildParams::default());
    let sweep = sah(&s.positions, &BuildParams { strategy: Strategy::Sweep, ..Default::default() });
    assert_eq!(BuildParams::default().bins, 16);
    assert!(
        binned <= sweep * 1.015,
        "16 bins: SAH {binned:.4}, sweep {sweep:.4} ({:+.2} %)",
        (binned / sweep - 1.0) * 100.0
    );
}

/// The procedural room: its root's cheapest split by the SAH (walls, floor and ceiling against
/// the objects and the mirror) was 4.85 % above the sweep's tree under every bin rule; the
/// reinsertion in the top of the tree (`bvh_build`'s `top` module) repairs it.
#[test]
fn sixteen_bins_stay_within_one_and_a_half_percent_of_the_sweep_in_the_room() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/room.toml");
    let s = load(&scene, &ImportOptions::default()).expect("the room imports");
    let binned = sah(&s.positions, &BuildParams::default());
    let sweep = sah(&s.positions, &BuildParams { strategy: Strategy::Sweep, ..Default::default() });
    assert!(
        binned <= sweep * 1.015,
        "16 bins: SAH {binned:.4}, sweep {sweep:.4} ({:+.2} %)",
        (binned / sweep - 1.0) * 100.0
    );
}
