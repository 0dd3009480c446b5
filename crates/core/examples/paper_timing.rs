//! Times the paper experiment (80 s at 1 ms) in pure Rust: the simulator vs the bare
//! recurrence. `cargo run --release --example paper_timing [sim|bare|friction] [reps]`
//! (`friction`: the simulator with Coulomb friction and stiction on both inertias).
use backlashkit_core::bare::bare_recurrence3;
use backlashkit_core::chain::{simulate_chain, ChainParams, Law};
use backlashkit_core::linalg::expm_and_integral;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let which = args.get(1).map(String::as_str).unwrap_or("both");
    let reps: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(300);
    let mut p = ChainParams {
        j: vec![4.88e-3, 6.8e-2],
        f: vec![0.5e-2, 0.5e-2],
        k: vec![78.0],
        d: vec![1.575e-2],
        theta: vec![3.49e-2],
        ..Default::default()
    };
    if which == "friction" {
        (p.fc, p.fs) = (vec![0.01, 0.02], vec![0.015, 0.03]);
    }
    let ts = 1e-3;
    let u: Vec<f64> = (0..80_001)
        .map(|i| if (i as f64) * ts < 40.0 { 0.157 } else { 0.0 })
        .collect();
    let (jm, jl, k, fm, fl, fs) = (4.88e-3, 6.8e-2, 78.0, 0.5e-2, 0.5e-2, 1.575e-2);
    let a = [
        [-(fm + fs) / jm, fs / jm, -k / jm],
        [fs / jl, -(fl + fs) / jl, k / jl],
        [1.0, -1.0, 0.0],
    ];
    let (e, f) = expm_and_integral(&a, ts);
    let fb = [f[0][0] / jm, f[1][0] / jm, f[2][0] / jm];
    let mut best = [f64::INFINITY; 2];
    for _ in 0..reps {
        if which != "bare" {
            let t0 = Instant::now();
            let out = simulate_chain(&p, Law::Paper, 0.0, ts, &u, &[0.0; 3]).unwrap();
            std::hint::black_box(&out);
            best[0] = best[0].min(t0.elapsed().as_secs_f64());
        }
        if which != "sim" {
            let t0 = Instant::now();
            let out = bare_recurrence3(&e, &fb, &[0.0; 3], &u, &[0.0; 3]);
            std::hint::black_box(&out);
            best[1] = best[1].min(t0.elapsed().as_secs_f64());
        }
    }
    println!(
        "simulator {:.3} ms, bare {:.3} ms (best of {reps})",
        best[0] * 1e3,
        best[1] * 1e3
    );
}
