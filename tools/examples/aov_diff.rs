//! How the primary hits of two AOV files of one frame differ (`render --aov`): for comparing
//! trace-vk's methods with one another (tools/scripts/h100-rtpipe.sh).
//!
//! ```text
//! cargo run --release -p tools --example aov_diff -- A.exr B.exr
//! ```
//! prints one line: `same N ties M differ K`, where a tie is another triangle at the same distance
//! (render_spec::Aovs::prim_diff, the cross-backend tests' rule), and exits with 0 whether or not
//! they differ (1 when a file cannot be read or the sizes differ).

fn main() {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    if paths.len() != 2 || paths.iter().any(|p| p == "-h" || p == "--help") {
        eprintln!("aov_diff A.exr B.exr: pixels whose primary hit is the same triangle, a tie, or another");
        std::process::exit(1);
    }
    let read = |p: &str| tools::output::read_aov(std::path::Path::new(p)).unwrap_or_else(|e| fail(&e));
    let ((wa, ha, a), (wb, hb, b)) = (read(&paths[0]), read(&paths[1]));
    if (wa, ha) != (wb, hb) {
        fail(&format!("{} is {wa}x{ha} pixels and {} is {wb}x{hb}", paths[0], paths[1]));
    }
    let d = a.prim_diff(&b);
    let total = wa as usize * ha as usize;
    println!("same {} ties {} differ {}", total - d.ties - d.differs, d.ties, d.differs);
}

fn fail(msg: &str) -> ! {
    eprintln!("aov_diff: {msg}");
    std::process::exit(1);
}
