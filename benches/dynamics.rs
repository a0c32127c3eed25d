//! Cost of the generated discrete dynamics and their Jacobians (the work per
//! shooting node of an RTI step), per shipped model: `cargo bench -p uavgen-benches`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};

const X: [f64; 12] = [1.0, -2.0, 5.0, 0.2, -0.1, 0.7, 1.5, -0.5, 0.3, 0.4, -0.2, 0.1];
const U: [f64; 4] = [0.5, 0.1, -0.2, 0.3];

macro_rules! bench_model {
    ($c:expr, $krate:ident) => {{
        let name = stringify!($krate);
        let x = X.map(|v| v as $krate::Real);
        let u = U.map(|v| v as $krate::Real);
        $c.bench_function(&format!("{name}/discrete_dynamics"), |b| {
            b.iter(|| $krate::discrete_dynamics(black_box(&x), black_box(&u)))
        });
        $c.bench_function(&format!("{name}/discrete_linearization"), |b| {
            b.iter(|| $krate::discrete_linearization(black_box(&x), black_box(&u)))
        });
    }};
}

fn dynamics(c: &mut Criterion) {
    bench_model!(c, pd_paper);
    bench_model!(c, pd_hover);
    bench_model!(c, pd_hover_f32);
    bench_model!(c, sindy_m100);
}

criterion_group!(benches, dynamics);
criterion_main!(benches);
