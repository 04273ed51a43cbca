//! The memory estimates that refuse runs too large for the machine estimate what is allocated:
//! never less than the peak of the heap (a run they let through fits), and not several times
//! more (a run that fits is not refused). Measured by a global allocator that tracks the bytes
//! live on the heap and their peak.
use hushfuse::engine::replay::{self, ReplayOptions};
use hushfuse::scenario::build::LoadOptions;
use hushfuse::scenario::limits::Limits;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

struct Peak;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(bytes: usize) {
    let now = LIVE.fetch_add(bytes, Relaxed) + bytes;
    PEAK.fetch_max(now, Relaxed);
}

unsafe impl GlobalAlloc for Peak {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        grew(layout.size());
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Relaxed);
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size >= layout.size() {
            grew(new_size - layout.size());
        } else {
            LIVE.fetch_sub(layout.size() - new_size, Relaxed);
        }
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static PEAK_ALLOC: Peak = Peak;

/// A recording of `steps` steps for examples/replay/scenario.toml (four sensors: two scalar,
/// two of dimension 2), every reading present.
fn recording(steps: usize) -> String {
    let mut s = String::from("step,sensor,z0,z1\n");
    for k in 1..=steps {
        let z = (k % 17) as f64 * 0.37 - 2.9;
        s += &format!(
            "{k},0,{z},\n{k},1,{},\n{k},2,{z},{}\n{k},3,{},{z}\n",
            z + 0.1,
            z - 0.3,
            z * 0.5
        );
    }
    s
}

/// The peak heap of `f` above what was live before it.
fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let before = LIVE.load(Relaxed);
    PEAK.store(before, Relaxed);
    let out = f();
    (out, PEAK.load(Relaxed) - before)
}

#[test]
fn the_replay_estimate_is_what_the_replay_allocates() {
    let scenario = std::fs::read_to_string("examples/replay/scenario.toml").unwrap();
    for steps in [20_000, 100_000] {
        let text = recording(steps);
        let opts = ReplayOptions {
            load: LoadOptions {
                limits: Some(Limits::none()),
                threads: 1,
                ..LoadOptions::default()
            },
            ..ReplayOptions::default()
        };
        let (_, peak) = peak_of(|| {
            let r = replay::replay_csv(&scenario, "scenario.toml", (&text, "m.csv"), None, &opts)
                .unwrap();
            let csv = replay::estimates_csv(&r.exp, &r.recorded, &r.replayed);
            csv.len()
        });
        let (estimate, _) = replay::estimated_bytes(
            &scenario,
            "scenario.toml",
            4 * steps,
            steps,
            false,
            &opts.load,
            None,
        )
        .unwrap();
        let ratio = estimate / peak as f64;
        eprintln!("{steps} steps: peak {peak} B, estimate {estimate:.0} B, ratio {ratio:.2}");
        assert!(
            ratio >= 1.0,
            "{steps} steps: the estimate is below the peak ({ratio:.2})"
        );
        assert!(
            ratio <= 1.5,
            "{steps} steps: the estimate is {ratio:.2} times the peak"
        );
    }
}

/// Drawing one trial (Python's `simulate`) builds no scheme: a run refused as too large for the
/// machine (10 000 variants' sums and plans over 10⁶ steps) is drawn, with the same data as
/// the full load draws.
#[test]
fn drawing_a_trial_is_checked_for_one_trial_s_data() {
    use hushfuse::engine::runner::draw_trial;
    use hushfuse::scenario::build;
    let text = hushfuse::scenario::builtin::get("dormann-fig1").unwrap();
    let limits = Limits {
        max_memory_bytes: 2e9,
        max_seconds: f64::INFINITY,
    };
    let long = text.replace("steps = 100\n", "steps = 1000000\n");
    let full = LoadOptions {
        limits: Some(limits),
        ..LoadOptions::default()
    };
    let e = build::load_with(&long, "long.toml", &full).unwrap_err();
    assert!(e.to_string().contains("memory"), "{e}");
    let data_only = LoadOptions {
        data_only: true,
        ..full
    };
    let exp = build::load_with(&long, "long.toml", &data_only).unwrap();
    assert!(exp.variants.is_empty() && exp.steps == 1_000_000);
    // The same draws as a full load of the scenario (at its own length).
    let short_full = build::load_with(text, "d.toml", &LoadOptions::default()).unwrap();
    let short_data = build::load_with(
        text,
        "d.toml",
        &LoadOptions {
            data_only: true,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    let (a, b) = (draw_trial(&short_full, 3), draw_trial(&short_data, 3));
    assert_eq!(a.truth, b.truth);
    assert_eq!(a.measurements, b.measurements);
}
