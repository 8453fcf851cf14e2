//! Prints what a scene file builds: nodes, curves with their node sequences and lengths.
//! `cargo run --example scene_info -- config/scenes/torus.toml`
fn main() {
    for arg in std::env::args().skip(1) {
        match sfs::simulate::scene::load(std::path::Path::new(&arg)) {
            Ok(s) => {
                println!(
                    "{}: {} nodes, {} curves, bbox diagonal {:.3} m",
                    s.name,
                    s.nodes.len(),
                    s.curves.len(),
                    s.bbox_diagonal()
                );
                for (i, c) in s.curves.iter().enumerate() {
                    let len: f64 = c.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
                    println!(
                        "  curve {i}: nodes {:?}, {} points, {:.3} m{}{}",
                        c.nodes(),
                        c.points.len(),
                        len,
                        if c.closed { ", closed" } else { "" },
                        match c.kind {
                            sfs::simulate::operator::CurveKind::Interior => String::new(),
                            k => format!(", {k}"),
                        }
                    );
                }
            }
            Err(e) => println!("error: {e}"),
        }
    }
}
