//! How two 8-bit images of one size differ, pixel by pixel: for comparing trace-vk's images with
//! trace-cpu's (tools/scripts/h100-exact.sh).
//!
//! ```text
//! cargo run --release -p tools --example image_diff -- A.png B.png
//! ```
//! prints one line: `identical N different M max-channel-difference K` (K in 1/255 steps), and
//! exits with 0 whether or not they differ (1 when an image cannot be read or the sizes differ).

fn main() {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    if paths.len() != 2 || paths.iter().any(|p| p == "-h" || p == "--help") {
        eprintln!("image_diff A B: identical and different pixel counts of two images of one size");
        std::process::exit(1);
    }
    let open = |p: &str| match image::open(p) {
        Ok(i) => i.into_rgb8(),
        Err(e) => fail(&format!("{p} could not be read: {e}")),
    };
    let (a, b) = (open(&paths[0]), open(&paths[1]));
    if a.dimensions() != b.dimensions() {
        fail(&format!("{} is {:?} pixels and {} is {:?}", paths[0], a.dimensions(), paths[1], b.dimensions()));
    }
    let mut different = 0u64;
    let mut max = 0u8;
    for (p, q) in a.pixels().zip(b.pixels()) {
        if p != q {
            different += 1;
            max = max.max(p.0.iter().zip(q.0).map(|(x, y)| x.abs_diff(y)).max().unwrap_or(0));
        }
    }
    let total = u64::from(a.width()) * u64::from(a.height());
    println!("identical {} different {different} max-channel-difference {max}", total - different);
}

fn fail(msg: &str) -> ! {
    eprintln!("image_diff: {msg}");
    std::process::exit(1);
}
