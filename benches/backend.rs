//! Primitive operations per backend: a GNS-sized matmul, and the gather and scatter-add that
//! carry per-edge messages and particle-to-grid transfers.
//!
//! `cargo bench --bench backend --features tch` (add `-- matmul` etc. to filter).

mod common;

use common::force;
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use phi_core::{Backend, IntTensor, Tensor};

/// Rows of the gather/scatter benches, their table size and their width (a GNS latent size).
const ROWS: usize = 100_000;
const TABLE: usize = 10_000;
const WIDTH: usize = 128;

fn bench_backend<B: Backend>(c: &mut Criterion) {
    let device = B::default_device();
    let name = B::name();

    let x = Tensor::<B>::random_uniform(&[8192, 128], -1.0, 1.0, 1, &device);
    let w = Tensor::<B>::random_uniform(&[128, 128], -1.0, 1.0, 2, &device);
    c.bench_with_input(
        BenchmarkId::new("matmul 8192x128x128", name),
        &(),
        |b, _| b.iter(|| force(&x.matmul(&w).unwrap())),
    );

    let table = Tensor::<B>::random_uniform(&[TABLE, WIDTH], -1.0, 1.0, 3, &device);
    let indices: Vec<i64> = (0..ROWS as i64)
        .map(|i| (i * 7919) % TABLE as i64)
        .collect();
    let indices = IntTensor::<B>::from_vec(indices, &[ROWS], &device).unwrap();
    c.bench_with_input(
        BenchmarkId::new("gather 100k rows of 128", name),
        &(),
        |b, _| b.iter(|| force(&table.gather_rows(&indices).unwrap())),
    );

    let values = Tensor::<B>::random_uniform(&[ROWS, WIDTH], -1.0, 1.0, 4, &device);
    let zeros = Tensor::<B>::zeros(&[TABLE, WIDTH], &device);
    c.bench_with_input(
        BenchmarkId::new("scatter-add 100k rows of 128 into 10k", name),
        &(),
        |b, _| b.iter(|| force(&zeros.scatter_add_rows(&indices, &values).unwrap())),
    );
}

fn benches(c: &mut Criterion) {
    phi_core::for_each_backend!(B => bench_backend::<B>(c));
}

criterion_group! {
    name = backend;
    config = Criterion::default().sample_size(20).measurement_time(std::time::Duration::from_secs(4));
    targets = benches
}
criterion_main!(backend);
