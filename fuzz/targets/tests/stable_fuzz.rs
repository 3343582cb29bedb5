//! The fuzz targets on stable, in `cargo test`: for each target, every file of
//! `fuzz/corpus/<target>/` (seeds and kept regressions), then deterministic mutations of each
//! ([`fuzz_targets::mutate`], stacked 1 to 3 rounds deep) and generated inputs
//! ([`fuzz_targets::generate`]).
//!
//! Each input runs under `catch_unwind` (a panic is a finding), a watchdog (an input that takes
//! more than 2 s is a hang) and an allocation guard (one allocation over 1 GiB, or more than
//! 4 GiB live, is an unbounded allocation: the guard names the input and aborts, as the
//! process could not survive it anyway). A failure names the target, the corpus file and the
//! mutation seed; regenerate that input with
//!
//! ```text
//! HB_FUZZ_INPUT=<target>/<file>/<mutation seed> cargo test --release -p fuzz-targets \
//!     --test stable_fuzz -- --ignored reproduce --nocapture
//! ```
//!
//! which writes it to `target/fuzz-input` and runs it outside `catch_unwind` (a backtrace with
//! RUST_BACKTRACE=1). A generated input is `<target>/generated/<seed>`.
//!
//! How many: `HB_FUZZ_MUTATIONS` mutations per corpus file and `HB_FUZZ_GENERATED` generated
//! inputs per target override the defaults ([`budget`]), which keep the whole test under a
//! minute on two cores in release.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::io::Write as _;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// An input that runs longer than this is a hang.
const HANG: Duration = Duration::from_secs(2);
/// One allocation larger than this is an unbounded allocation.
const MAX_ALLOCATION: usize = 1 << 30;
/// More live heap than this (the whole test process) is one too.
const MAX_LIVE: usize = 4 << 30;
/// Failures kept per target before it stops.
const MAX_FAILURES: usize = 5;

/// The allocation guard: forwards to the system allocator, and aborts naming the input when an
/// allocation is unbounded.
struct Guard;

static LIVE: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// The input this thread runs: target, corpus file (or "generated"), mutation seed.
    static CURRENT: Cell<Option<(&'static str, &'static str, Option<u64>)>> =
        const { Cell::new(None) };
}

fn too_big(size: usize) -> bool {
    size > MAX_ALLOCATION || LIVE.load(Ordering::Relaxed).saturating_add(size) > MAX_LIVE
}

#[cold]
fn unbounded(size: usize) -> ! {
    let what = CURRENT.try_with(|c| c.get()).ok().flatten();
    let live = LIVE.load(Ordering::Relaxed);
    let mut err = std::io::stderr();
    let _ = match what {
        Some((target, file, seed)) => writeln!(
            err,
            "UNBOUNDED ALLOCATION: target {target}, corpus file {file}, mutation seed {seed:?}: \
             an allocation of {size} bytes with {live} bytes live"
        ),
        None => writeln!(err, "UNBOUNDED ALLOCATION of {size} bytes ({live} live)"),
    };
    // Where it came from (capturing allocates a little, which this guard lets through).
    let _ = writeln!(err, "{}", std::backtrace::Backtrace::force_capture());
    std::process::abort()
}

// SAFETY: forwards every call to the system allocator unchanged and only counts bytes; it
// never unwinds (an unbounded request aborts the process).
unsafe impl GlobalAlloc for Guard {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if too_big(layout.size()) {
            unbounded(layout.size());
        }
        LIVE.fetch_add(layout.size(), Ordering::Relaxed);
        // SAFETY: the caller upholds `GlobalAlloc::alloc`'s contract, which is the system's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if too_big(layout.size()) {
            unbounded(layout.size());
        }
        LIVE.fetch_add(layout.size(), Ordering::Relaxed);
        // SAFETY: as for `alloc`.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        // SAFETY: `ptr` came from this allocator, i.e. from the system's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if (new_size > layout.size() && too_big(new_size - layout.size()))
            || new_size > MAX_ALLOCATION
        {
            unbounded(new_size);
        }
        LIVE.fetch_add(new_size, Ordering::Relaxed);
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        // SAFETY: as for `dealloc`, and the caller upholds `realloc`'s contract.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Guard = Guard;

fn corpus(target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/corpus")
        .join(target)
}

/// The corpus files of a target, by name.
fn corpus_files(target: &str) -> Vec<(&'static str, Vec<u8>)> {
    let dir = corpus(target);
    let mut files: Vec<(&'static str, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| {
            let path = e.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            (
                &*Box::leak(name.into_boxed_str()),
                std::fs::read(&path).unwrap(),
            )
        })
        .collect();
    if target == "carl" {
        // The real recordings beside the checkout (not ours to check in), their first 64 KiB
        // (about 45 samples, cut mid-sample: the reader keeps the good ones).
        let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/carl");
        for e in std::fs::read_dir(&shared).into_iter().flatten().flatten() {
            let path = e.path();
            if path.extension().is_some_and(|x| x == "carl") {
                let mut bytes = std::fs::read(&path).unwrap();
                bytes.truncate(64 << 10);
                let name = format!("shared-{}", path.file_name().unwrap().to_string_lossy());
                files.push((&*Box::leak(name.into_boxed_str()), bytes));
            }
        }
    }
    files.sort();
    files
}

/// Text targets get mostly printable generated inputs.
fn is_text(target: &str) -> bool {
    matches!(target, "scene" | "session" | "hand" | "calibration")
}

/// Generated input `seed` of a target: [`fuzz_targets::generate`]'s bytes, after the magic
/// and header of the binary formats (their first seed's), so that they reach the parser.
fn generated_input(target: &str, files: &[(&'static str, Vec<u8>)], seed: u64, out: &mut Vec<u8>) {
    fuzz_targets::generate(seed, is_text(target), out);
    let header = match target {
        "mcap" => 8,  // the magic
        "carl" => 20, // the magic, version, type and count
        _ => 0,
    };
    if let Some((_, first)) = files.iter().find(|(n, _)| n.starts_with("seed-")) {
        let header = header.min(first.len());
        out.splice(0..0, first[..header].iter().copied());
    }
}

/// Mutation `seed` of a corpus file: 1 to 3 rounds of [`fuzz_targets::mutate`].
fn mutant(file: &[u8], seed: u64, out: &mut Vec<u8>) {
    let rounds = 1 + seed % 3;
    let mut prev = file.to_vec();
    for r in 0..rounds {
        fuzz_targets::mutate(seed.wrapping_add(r << 48), &prev, out);
        std::mem::swap(&mut prev, out);
    }
    std::mem::swap(&mut prev, out);
}

/// Mutations per corpus file and generated inputs, per target (inputs that read files or
/// build many blocks cost more), unless `HB_FUZZ_MUTATIONS` / `HB_FUZZ_GENERATED` say.
fn budget(target: &str) -> (u64, u64) {
    // Measured on the 2-vCPU VM in release: the byte parsers run 150k-450k inputs a second,
    // the file targets (a file written and read, TOML parsed) about 3.5k, and a third of that
    // while another build shares the CPUs: 10 to 30 s on two cores.
    let (m, g) = match target {
        "cyberglove" | "fastrak" | "link" | "webxr" => (100_000, 100_000),
        "calibration" => (50_000, 50_000),
        "carl" => (30_000, 30_000),
        "mcap" => (15_000, 15_000),
        "hand" => (6_000, 4_000),
        "scene" | "session" => (2_000, 3_000),
        // 48 steps of a small scene an input, half of them under rapier: ~1 ms an input.
        "stepper_hand" => (400, 400),
        _ => (1_000, 1_000),
    };
    let env = |k: &str, d: u64| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    (env("HB_FUZZ_MUTATIONS", m), env("HB_FUZZ_GENERATED", g))
}

/// What the watchdog sees: the input running now and since when, and how many ran.
#[derive(Default)]
struct Progress {
    running: Option<(String, Instant)>,
    inputs: u64,
    failures: Vec<String>,
    done: bool,
}

fn label(target: &str, file: &str, seed: Option<u64>) -> String {
    match seed {
        None => format!("target {target}, corpus file fuzz/corpus/{target}/{file} as is"),
        Some(s) if file == "generated" => {
            format!(
                "target {target}, generated input, seed {s} (HB_FUZZ_INPUT={target}/generated/{s})"
            )
        }
        Some(s) => format!(
            "target {target}, corpus file fuzz/corpus/{target}/{file}, mutation seed {s} \
             (HB_FUZZ_INPUT={target}/{file}/{s})"
        ),
    }
}

fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<String>()
        .cloned()
        .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_else(|| "a panic without a message".into())
}

/// Runs every input of `target` on a worker thread, watched from this one.
fn run(target: &'static str) {
    let f = fuzz_targets::target(target).expect("a target");
    let (mutations, generated) = budget(target);
    let progress = Arc::new(Mutex::new(Progress::default()));
    let started = Instant::now();
    let worker = {
        let progress = Arc::clone(&progress);
        std::thread::Builder::new()
            .name(format!("fuzz-{target}"))
            .spawn(move || {
                let files = corpus_files(target);
                let mut input = Vec::new();
                let one = |file: &'static str, seed: Option<u64>, input: &[u8]| -> bool {
                    {
                        let mut p = progress.lock().unwrap();
                        p.running = Some((label(target, file, seed), Instant::now()));
                    }
                    CURRENT.with(|c| c.set(Some((target, file, seed))));
                    let outcome = catch_unwind(AssertUnwindSafe(|| f(input)));
                    CURRENT.with(|c| c.set(None));
                    let mut p = progress.lock().unwrap();
                    p.inputs += 1;
                    if let Err(e) = outcome {
                        let what = p.running.take().map(|r| r.0).unwrap_or_default();
                        p.failures
                            .push(format!("{what}: panicked: {}", panic_text(&*e)));
                    }
                    p.running = None;
                    p.failures.len() < MAX_FAILURES
                };
                'all: {
                    for (name, bytes) in &files {
                        if !one(name, None, bytes) {
                            break 'all;
                        }
                    }
                    for (name, bytes) in &files {
                        for s in 0..mutations {
                            mutant(bytes, s, &mut input);
                            if !one(name, Some(s), &input) {
                                break 'all;
                            }
                        }
                    }
                    for s in 0..generated {
                        generated_input(target, &files, s, &mut input);
                        if !one("generated", Some(s), &input) {
                            break 'all;
                        }
                    }
                }
                fuzz_targets::remove_scratch_dir();
                progress.lock().unwrap().done = true;
            })
            .expect("a worker thread")
    };
    loop {
        std::thread::sleep(Duration::from_millis(20));
        let p = progress.lock().unwrap();
        if p.done {
            break;
        }
        if let Some((what, since)) = &p.running {
            if since.elapsed() > HANG {
                panic!(
                    "{what}: HANG: still running after {:.1} s (more than {} s)",
                    since.elapsed().as_secs_f64(),
                    HANG.as_secs()
                );
            }
        }
    }
    worker.join().expect("the worker ends");
    let p = progress.lock().unwrap();
    let files = corpus_files(target).len();
    let secs = started.elapsed().as_secs_f64();
    let _ = writeln!(
        std::io::stderr(),
        "stable fuzz: {target:<12} {:>8} inputs ({files} corpus files, {mutations} mutations each, \
         {generated} generated) in {secs:.1} s ({:.0} inputs/s)",
        p.inputs,
        p.inputs as f64 / secs
    );
    assert!(
        p.failures.is_empty(),
        "{} finding(s) in {target}:\n{}",
        p.failures.len(),
        p.failures.join("\n")
    );
}

#[test]
fn cyberglove() {
    run("cyberglove");
}

#[test]
fn fastrak() {
    run("fastrak");
}

#[test]
fn carl() {
    run("carl");
}

// Issue 16: mcap 0.26's record parser allocated a string's claimed u32 length before checking
// that the record holds it (HB_FUZZ_INPUT=mcap/seed-cut-off/62: 1.6 GiB from 7 KiB); our reader
// now checks every length first (fuzz/corpus/mcap/regression-metadata-string-length).
#[test]
fn mcap() {
    run("mcap");
}

#[test]
fn scene() {
    run("scene");
}

#[test]
fn session() {
    run("session");
}

#[test]
fn hand() {
    run("hand");
}

#[test]
fn calibration() {
    run("calibration");
}

#[test]
fn link() {
    run("link");
}

#[test]
fn webxr() {
    run("webxr");
}

#[test]
fn stepper_hand() {
    run("stepper_hand");
}

/// Regenerates one input named by a failure (`HB_FUZZ_INPUT=<target>/<file>/<seed>`, or
/// `<target>/<file>` for a corpus file as is), writes it to `target/fuzz-input` and runs it
/// outside `catch_unwind`.
#[test]
#[ignore = "run by hand with HB_FUZZ_INPUT set"]
fn reproduce() {
    let Ok(spec) = std::env::var("HB_FUZZ_INPUT") else {
        eprintln!("set HB_FUZZ_INPUT=<target>/<corpus file or generated>/<seed>");
        return;
    };
    let parts: Vec<&str> = spec.split('/').collect();
    let (target, file, seed) = match parts[..] {
        [t, f] => (t, f, None),
        [t, f, s] => (t, f, Some(s.parse::<u64>().expect("a seed number"))),
        _ => panic!("HB_FUZZ_INPUT={spec}: give <target>/<file>/<seed>"),
    };
    let mut input = Vec::new();
    match (file, seed) {
        ("generated", Some(s)) => generated_input(target, &corpus_files(target), s, &mut input),
        (f, s) => {
            let bytes = std::fs::read(corpus(target).join(f)).expect("the corpus file");
            match s {
                Some(s) => mutant(&bytes, s, &mut input),
                None => input = bytes,
            }
        }
    }
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/fuzz-input");
    std::fs::write(&out, &input).expect("target/fuzz-input");
    eprintln!("{spec}: {} bytes written to {}", input.len(), out.display());
    fuzz_targets::target(target).expect("a target")(&input);
    fuzz_targets::remove_scratch_dir();
}
