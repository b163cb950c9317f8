//! Issue 16's table, re-measured side by side: rays aimed exactly at shared edges and shared
//! vertices of a camera grid (tools/src/stress/edge_grid.rs; 512 x 512 pixel rays by default), and
//! how many slip through (hit nothing) with our default edge-consistent test, with Möller-Trumbore
//! (`--intersect mt`), and with Embree on the very same rays and triangles, in its default and its
//! robust mode. Ours go through the whole CPU renderer (`tracer_cpu::render`, ordered traversal);
//! Embree through `rtcIntersect1`.
//!
//! cargo run --release -p tools --features embree --example leak_table [-- N]

use render_spec::{Accuracy, Intersect, NO_TRIANGLE, Settings};
use tools::stress::edge_grid::{Aim, camera_grid, cast_settings};
use tracer_cpu::embree::{Flags, Scene as Embree};
use tracer_cpu::geometry::Ray;
use tracer_cpu::{Method, Tracer};

fn main() -> Result<(), String> {
    let n: u32 = match std::env::args().nth(1) {
        Some(a) => a.parse().map_err(|_| format!("{a:?} is not a pixel count"))?,
        None => 512,
    };
    println!("{n} x {n} = {} rays per grid; a leak is a ray that hits nothing.\n", n * n);
    println!(
        "| eye distance | aimed at | ours (edge-consistent) | ours (Möller-Trumbore) | Embree default | Embree robust |"
    );
    println!("|---:|---|---:|---:|---:|---:|");
    for aim in [Aim::Edges, Aim::Vertices] {
        for distance in [1.0f32, 10.0, 100.0, 1000.0, 10_000.0] {
            let (scene, cam, _) = camera_grid(n, distance, aim)?;
            let tracer = Tracer::new(&scene);
            let ours = |intersect| -> Result<usize, String> {
                let settings =
                    Settings { accuracy: Accuracy { intersect, ..Default::default() }, ..cast_settings(cam, n) };
                let img = tracer_cpu::render(&tracer, &settings, Method::Ordered).map_err(|e| e.to_string())?;
                let prim = img.aov.ok_or("the renderer returned no AOVs")?.prim;
                Ok(prim.iter().filter(|&&p| p == NO_TRIANGLE).count())
            };
            let frame = cam.frame(n, n).map_err(|e| format!("{e:?}"))?;
            let embree = |flags| -> Result<usize, String> {
                let em = Embree::new(&scene.leaf_triangles(), flags)?;
                Ok((0..n * n)
                    .filter(|&i| {
                        let ray = Ray::new(cam.eye, frame.direction(i % n, i / n));
                        em.intersect1(&ray, 0.0, f32::INFINITY).is_none()
                    })
                    .count())
            };
            println!(
                "| {distance} | {} | {} | {} | {} | {} |",
                match aim {
                    Aim::Edges => "shared edges",
                    Aim::Vertices => "shared vertices",
                },
                ours(Intersect::Watertight)?,
                ours(Intersect::MollerTrumbore)?,
                embree(Flags::Default)?,
                embree(Flags::Robust)?
            );
        }
    }
    Ok(())
}
