//! One hash per frame of `tracer_cpu::render::render` over scenes x modes x methods x outputs, to
//! compare two builds' images bit for bit (run both, diff the lines): the image, ray counts and
//! the distance, normal and triangle AOVs in one hash, the cost AOVs in another (auto's follow
//! the pick its timing makes, which can differ from run to run).
//!
//! ```text
//! cargo run --release -p tracer-cpu --example frame_hashes -- [SCENE ...] > hashes.txt
//! ```
//! Scenes are .bvh files or descriptions (compiled with the default settings) [default: the
//! repository's room, bunny, car and forest]; frames are 200x150 from the "medium" camera.

#[path = "../benches/rayset/mod.rs"]
mod rayset;

use render_spec::{Accuracy, Ao, CameraSpec, Mode, Settings};
use std::hash::{Hash, Hasher};
use std::path::PathBuf;
use tracer_cpu::{Method, Tracer};

fn main() {
    let mut scenes: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    if scenes.is_empty() {
        let dir = rayset::scenes_dir();
        scenes = ["room", "bunny", "car", "forest"].iter().map(|s| dir.join(format!("{s}.toml"))).collect();
    }
    let methods = ["packet", "bvh8", "ordered", "auto", "bvh8-packet"];
    for path in &scenes {
        let scene = rayset::open(path).unwrap_or_else(|e| panic!("{e}"));
        let tracer = Tracer::new(&scene);
        let camera = CameraSpec::from(scene.camera("medium").expect("a medium camera"));
        for mode in [Mode::Cast, Mode::Whitted, Mode::Ao(Ao::default()), Mode::Diffuse] {
            for name in methods {
                let method = Method::named(name).expect("a method");
                for (aovs, spp) in [(false, 1), (true, 1), (true, 4)] {
                    let settings = Settings {
                        aovs,
                        accuracy: Accuracy { spp, ..Default::default() },
                        ..Settings::of_scene(&scene, camera, mode, (200, 150))
                    };
                    let image = tracer_cpu::render::render(&tracer, &settings, method).expect("renders");
                    // Everything but the cost AOVs, then those.
                    let mut h = std::collections::hash_map::DefaultHasher::new();
                    image.rgb.hash(&mut h);
                    format!("{:?}", image.rays).hash(&mut h);
                    let mut costs = std::collections::hash_map::DefaultHasher::new();
                    if let Some(a) = &image.aov {
                        a.t.iter().for_each(|t| t.to_bits().hash(&mut h));
                        a.normal.iter().flatten().for_each(|n| n.to_bits().hash(&mut h));
                        a.prim.hash(&mut h);
                        (&a.nodes, &a.tris).hash(&mut costs);
                    }
                    let note = if name == "auto" && aovs { " (auto's cost AOVs follow its timing)" } else { "" };
                    println!(
                        "{} {mode:?} {name} aovs={aovs} spp={spp}: {:016x} costs {:016x}{note}",
                        path.file_stem().unwrap_or_default().to_string_lossy(),
                        h.finish(),
                        costs.finish()
                    );
                }
            }
        }
    }
}
