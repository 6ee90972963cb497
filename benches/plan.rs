//! Pose planning (`drawcal plan`): 10,000 valid candidates down to 30
//! poses on the ER3A's four-string rig, and how the time grows with the
//! candidates and the poses. BENCHMARKS.md quotes it:
//!
//!     cargo bench --bench plan

use criterion::{Criterion, criterion_group, criterion_main};
use drawcal::physics::simulate::preset;
use drawcal::plan::{PlanOptions, plan};

fn planning(c: &mut Criterion) {
    let (robot, rig, _) = preset("er3a").expect("a preset");
    let mut g = c.benchmark_group("plan");
    g.sample_size(10);
    for (candidates, n) in [(10_000, 30), (2_500, 30), (20_000, 30), (10_000, 60)] {
        let mut opts = PlanOptions::new(n);
        opts.candidates = candidates;
        g.bench_function(format!("er3a_{candidates}_candidates_to_{n}"), |b| {
            b.iter(|| plan(&robot, &rig, &opts).expect("a plan"))
        });
    }
    g.finish();
}

criterion_group!(benches, planning);
criterion_main!(benches);
