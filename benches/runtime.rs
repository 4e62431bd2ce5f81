//! Criterion benchmarks: the bus, a whole virtual episode against bare physics, recording
//! cost, brain inference, and the run core's capture and restore. Results and the commands live in BENCHMARKS.md.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use ratelab::checkpoint::load_policy;
use ratelab::plant::CartPole;
use ratelab::policy::Scripted;
use ratelab::qos::{apply_key, split_pairs, TopicQos};
use ratelab::recording::{RecordOptions, Recording};
use ratelab::topic::Subscription;
use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions};
use std::hint::black_box;
use std::path::Path;
use std::sync::Arc;

#[path = "support/baseline_topic.rs"]
mod baseline_topic;

/// One publish + one read per iteration on one thread, at a 20 ms publish period (run time
/// advances 20 ms per iteration, so a deadline of 40 ms is never missed and a lifespan of
/// 60 ms never expires the message read): the pre-QoS topic (a frozen copy, the baseline)
/// against today's with every QoS setting off, with deadline + lifespan, FIFO delivery and
/// a lossy link, side by side in one group.
fn topic(c: &mut Criterion) {
    const PERIOD: u64 = 20_000_000;
    let mut g = c.benchmark_group("topic publish+read, 1 thread");
    {
        let t: baseline_topic::Topic<[f32; 5]> = baseline_topic::Topic::new("/obs", 1).unwrap();
        let mut i = 0u64;
        g.bench_function("baseline: pre-QoS topic (e7a8428), publish + latest", |b| {
            b.iter(|| {
                i += 1;
                t.publish(black_box([i as f32; 5]), Nanos(i * PERIOD), None);
                black_box(t.latest())
            })
        });
    }
    for (label, depth, pairs) in [
        ("QoS off (keep_last 1, latest)", 1, None),
        (
            "deadline 40 ms + lifespan 60 ms",
            1,
            Some("deadline_ms=40,lifespan_ms=60"),
        ),
        ("fifo, keep_last 100", 100, Some("delivery=fifo")),
        (
            "lossy link (5% loss, 1 ms delay, best effort)",
            1,
            Some("loss=0.05,delay_ms=1"),
        ),
    ] {
        let mut qos = TopicQos::default();
        let mut d = depth;
        for (k, v) in pairs.map(|p| split_pairs(p).unwrap()).unwrap_or_default() {
            apply_key(&mut qos, &mut d, k, v).unwrap();
        }
        let t: Subscription<[f32; 5]> = Subscription::with_qos("/obs", d, qos, 0).unwrap();
        let mut i = 0u64;
        g.bench_function(label, |b| {
            b.iter(|| {
                i += 1;
                let now = Nanos(i * PERIOD);
                t.publish(black_box([i as f32; 5]), now, None);
                black_box(t.read(now))
            })
        });
        // What the run measured is what was asked: nothing missed, expired or refused.
        let s = t.stats();
        assert_eq!(
            (s.offered_deadline_missed, s.expired, s.refused, s.dropped),
            (0, 0, 0, 0),
            "{label}: {s:?}"
        );
    }
    g.finish();
    // Two threads: a publisher hammering the topic while we publish+read.
    let shared: Arc<Subscription<[f32; 5]>> = Arc::new(Subscription::new("/obs", 1).unwrap());
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let other = {
        let (t, stop) = (shared.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut k = 0u64;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                k += 1;
                t.publish([0.0; 5], Nanos(k), None);
            }
        })
    };
    c.bench_function("topic/publish+read (2 threads, contended)", |b| {
        b.iter(|| {
            shared.publish(black_box([1.0; 5]), Nanos(0), None);
            black_box(shared.read(Nanos(0)))
        })
    });
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    other.join().unwrap();
}

fn episode(c: &mut Criterion) {
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        ..RunConfig::default()
    };
    let mut g = c.benchmark_group("episode (10 s virtual, 1000 physics steps)");
    g.bench_function(
        "bare MuJoCo: new plant + reset + 501 control steps (1002 mj_step)",
        |b| {
            b.iter(|| {
                let mut plant = CartPole::new().unwrap();
                plant.reset(0);
                let mut p = Scripted;
                for _ in 0..501 {
                    use ratelab::policy::Policy;
                    let a = p.act(&plant.observe());
                    black_box(plant.step(a[0]));
                }
            })
        },
    );
    g.bench_function("plant construction only (model copy + mjData)", |b| {
        b.iter(|| black_box(CartPole::new().unwrap()))
    });
    g.bench_function("ratelab graph: virtual run, 501 actuator ticks", |b| {
        b.iter(|| {
            black_box(
                run(
                    &cfg,
                    Box::new(Scripted),
                    RunOptions {
                        keep_trace: false,
                        ..Default::default()
                    },
                )
                .unwrap(),
            )
        })
    });
    g.bench_function("ratelab graph + rerun recording", |b| {
        let dir = tempfile::tempdir().unwrap();
        let mut n = 0;
        b.iter_batched(
            || {
                n += 1;
                let path = dir.path().join(format!("bench-{n}.rrd"));
                Recording::create(&path, &cfg, "scripted", &RecordOptions::default())
                    .unwrap()
                    .0
            },
            |rec| {
                let opts = RunOptions {
                    keep_trace: false,
                    observers: vec![Box::new(ratelab::observer::Recorded::new(&rec))],
                    ..Default::default()
                };
                let r = run(&cfg, Box::new(Scripted), opts).unwrap();
                rec.finish(&r.metrics, &r.end).unwrap();
            },
            BatchSize::PerIteration,
        )
    });
    g.finish();
}

/// The longest chain a graph may have (8 nodes): sensor (positions) → estimator → policy
/// → four safety nodes → actuator, everything at 50 Hz.
const EIGHT_NODES: &str = r#"
name = "eight"
[[node]]
name = "sensor"
kind = "sensor"
rate_hz = 50
publishes = "/meas"
[[node]]
name = "estimator"
kind = "estimator"
rate_hz = 50
subscribes = "/meas"
publishes = "/state"
[[node]]
name = "policy"
kind = "policy"
rate_hz = 50
subscribes = "/state"
publishes = "/f0"
[[node]]
name = "s1"
kind = "safety"
rate_hz = 50
subscribes = "/f0"
publishes = "/f1"
[[node]]
name = "s2"
kind = "safety"
rate_hz = 50
subscribes = "/f1"
publishes = "/f2"
[[node]]
name = "s3"
kind = "safety"
rate_hz = 50
subscribes = "/f2"
publishes = "/f3"
[[node]]
name = "s4"
kind = "safety"
rate_hz = 50
subscribes = "/f3"
publishes = "/f4"
[[node]]
name = "actuator"
kind = "actuator"
rate_hz = 50
subscribes = "/f4"
[[topic]]
name = "/meas"
type = "position"
depth = 1
[[topic]]
name = "/state"
type = "state"
depth = 1
[[topic]]
name = "/f0"
type = "force"
depth = 1
[[topic]]
name = "/f1"
type = "force"
depth = 1
[[topic]]
name = "/f2"
type = "force"
depth = 1
[[topic]]
name = "/f3"
type = "force"
depth = 1
[[topic]]
name = "/f4"
type = "force"
depth = 1
"#;

/// Per node tick: the chapter's 3-node graph against the 8-node chain, 10 s virtual runs
/// (criterion's throughput is node ticks, so the two rows compare per tick).
fn graph_size(c: &mut Criterion) {
    let mut g = c.benchmark_group("graph size (10 s virtual run, per node tick)");
    for (label, graph) in [
        (
            "3 nodes (graphs/cartpole.toml)",
            ratelab::graph::GraphSpec::chapter(),
        ),
        (
            "8 nodes (sensor, estimator, policy, 4 safety, actuator)",
            ratelab::graph::GraphSpec::parse(EIGHT_NODES, "eight").unwrap(),
        ),
    ] {
        let cfg = RunConfig {
            clock: ClockKind::Virtual,
            graph,
            ..RunConfig::default()
        };
        let ticks = 501 * cfg.graph.nodes.len() as u64;
        g.throughput(criterion::Throughput::Elements(ticks));
        g.bench_function(label, |b| {
            b.iter(|| {
                let r = run(
                    &cfg,
                    Box::new(Scripted),
                    RunOptions {
                        keep_trace: false,
                        ..Default::default()
                    },
                )
                .unwrap();
                assert!(r.metrics.balanced);
                black_box(r)
            })
        });
    }
    g.finish();
}

fn brains(c: &mut Criterion) {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/fixtures");
    let obs = [0.01f32, -0.02, 0.999, 0.03, 0.1];
    let mut g = c.benchmark_group("brain inference (one call)");
    g.bench_function("scripted", |b| {
        let mut p = Scripted;
        b.iter(|| {
            use ratelab::policy::Policy;
            black_box(p.act(black_box(&obs)))
        })
    });
    for name in ["ppo_ch2.1_seed0.pt", "ppo_ch2.1_seed0.onnx"] {
        let path = fixtures.join(name);
        if let Ok(mut p) = load_policy(path.to_str().unwrap()) {
            g.bench_function(name, |b| b.iter(|| black_box(p.act(black_box(&obs)))));
        }
    }
    g.finish();
}

fn exercises(c: &mut Criterion) {
    let bands = ratelab_exercises::load_bands(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("exercises/bands.toml"),
    )
    .unwrap();
    let mut g = c.benchmark_group("exercises");
    g.sample_size(10);
    g.bench_function("ex1 + ex2 measurement (24 ten-second virtual runs)", |b| {
        b.iter(|| {
            black_box(
                ratelab_exercises::measure_ex1(
                    &bands.of().unwrap(),
                    &ratelab::graph::GraphSpec::chapter(),
                    &ratelab::scheduler::StopFlag::new(),
                )
                .unwrap(),
            );
            black_box(
                ratelab_exercises::measure_ex2(
                    &bands.of().unwrap(),
                    &ratelab::graph::GraphSpec::chapter(),
                    &ratelab::scheduler::StopFlag::new(),
                )
                .unwrap(),
            );
        })
    });
    g.finish();
}

/// The run core ([`ratelab::runcore`]): a capture and a restore of the chapter's graph at
/// 5 s of a 10 s run (no trace kept, as the lab keeps none), and reaching an instant of a
/// 10-minute run by restoring the nearest of captures taken every 10 s and running on.
fn run_core(c: &mut Criterion) {
    use ratelab::runcore::{CoreOptions, RunCore};
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        ..RunConfig::default()
    };
    let core =
        |cfg: &RunConfig| RunCore::new(cfg, Box::new(Scripted), CoreOptions::default()).unwrap();
    let mut g = c.benchmark_group("run core (chapter graph)");
    let mut at5 = core(&cfg);
    at5.run_until(Nanos(5 * Nanos::SECOND.0));
    g.bench_function("capture at 5 s", |b| b.iter(|| black_box(at5.capture())));
    let cap = at5.capture();
    at5.run_until(Nanos(6 * Nanos::SECOND.0));
    g.bench_function("restore to 5 s", |b| {
        b.iter(|| at5.restore(black_box(&cap)).unwrap())
    });
    let long = RunConfig {
        duration: Nanos(600 * Nanos::SECOND.0),
        ..cfg.clone()
    };
    let mut ten_min = core(&long);
    let mut every_10_s = Vec::new();
    for s in (0..600).step_by(10) {
        ten_min.run_until(Nanos(s * Nanos::SECOND.0));
        every_10_s.push(ten_min.capture());
    }
    ten_min.run_until(long.duration);
    let mut k = 0u64;
    g.bench_function(
        "reach an instant of a 10-minute run (captures every 10 s)",
        |b| {
            b.iter(|| {
                // Instants spread over the run, none on a capture.
                k = (k + 7_919) % 599_000;
                let t = Nanos((k + 500) * Nanos::MILLISECOND.0);
                let nearest = &every_10_s[(t.0 / (10 * Nanos::SECOND.0)) as usize];
                ten_min.restore(nearest).unwrap();
                ten_min.run_until(t);
                black_box(ten_min.now())
            })
        },
    );
    g.finish();
}

criterion_group!(benches, topic, episode, graph_size, brains, exercises, run_core);
criterion_main!(benches);
