//! Stable, seeded fuzz runner: drives every target of `swing_fuzz` with the committed seed
//! corpus (`fuzz/corpus/<target>/`), mutations of it and fresh ChaCha-random bytes, for a
//! bounded time per target. No coverage feedback (that is what libFuzzer on nightly adds);
//! what it guarantees is that CI fuzzes on stable, reproducibly (`--seed`), and fails on a
//! finding.
//!
//! A finding is a panic (caught per input), an input slower than `--timeout-ms` twice in a
//! row, an input still running after ten times that (a hang: the watchdog saves it and
//! exits), or a single allocation above `--max-alloc-mb` (an unbounded allocation: saved,
//! then exit). The input is saved to `fuzz/artifacts/<target>/<kind>-<hash>`; replay it with
//! `run --target <target> --replay <file>`. Exit status: 0 clean, 1 finding, 2 usage.

use std::alloc::{GlobalAlloc, Layout, System};
use std::panic::{self, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use swing_fuzz::{Target, MAX_INPUT, TARGETS};

/// Refuses (reports and exits on) any single allocation above the cap.
struct CappedAlloc;

static ALLOC_CAP: AtomicUsize = AtomicUsize::new(usize::MAX);
static REPORTING: AtomicBool = AtomicBool::new(false);

unsafe impl GlobalAlloc for CappedAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if layout.size() > ALLOC_CAP.load(Ordering::Relaxed)
            && !REPORTING.swap(true, Ordering::SeqCst)
        {
            finding_exit(
                "alloc",
                &format!("a single allocation of {} bytes", layout.size()),
            );
        }
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > ALLOC_CAP.load(Ordering::Relaxed) && !REPORTING.swap(true, Ordering::SeqCst) {
            finding_exit("alloc", &format!("a reallocation to {new_size} bytes"));
        }
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: CappedAlloc = CappedAlloc;

/// The input being run, for the allocation and hang reports.
struct Current {
    target: String,
    input: Vec<u8>,
}

static CURRENT: Mutex<Option<Current>> = Mutex::new(None);
static STARTED_NS: AtomicU64 = AtomicU64::new(0);
static ARTIFACTS: OnceLock<PathBuf> = OnceLock::new();
static LAST_PANIC: Mutex<String> = Mutex::new(String::new());

fn epoch() -> Instant {
    static E: OnceLock<Instant> = OnceLock::new();
    *E.get_or_init(Instant::now)
}

fn now_ns() -> u64 {
    epoch().elapsed().as_nanos() as u64
}

fn fnv(data: &[u8]) -> u64 {
    data.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3)
    })
}

fn save(target: &str, kind: &str, input: &[u8]) -> PathBuf {
    let dir = ARTIFACTS
        .get()
        .cloned()
        .unwrap_or_else(|| PathBuf::from("artifacts"))
        .join(target);
    let _ = std::fs::create_dir_all(&dir);
    let path = dir.join(format!("{kind}-{:016x}", fnv(input)));
    let _ = std::fs::write(&path, input);
    path
}

/// Save the current input as a finding of `kind` and exit 1 (allocation cap or hang: the
/// process cannot go on safely).
fn finding_exit(kind: &str, what: &str) -> ! {
    let (target, input) = match CURRENT.try_lock() {
        Ok(g) => g
            .as_ref()
            .map(|c| (c.target.clone(), c.input.clone()))
            .unwrap_or_default(),
        Err(_) => (String::from("unknown"), Vec::new()),
    };
    let path = save(&target, kind, &input);
    eprintln!(
        "FINDING {kind} in {target}: {what}; input saved to {}",
        path.display()
    );
    std::process::exit(1);
}

struct Options {
    seconds: f64,
    seed: u64,
    timeout: Duration,
    max_alloc: usize,
    targets: Vec<String>,
    corpus: PathBuf,
    artifacts: PathBuf,
    replay: Option<PathBuf>,
}

fn usage(msg: &str) -> ! {
    eprintln!("run: {msg}");
    eprintln!(
        "usage: run [--seconds S] [--seed N] [--timeout-ms MS] [--max-alloc-mb MB] \
         [--target NAME]... [--corpus DIR] [--artifacts DIR] [--replay FILE] [--list]"
    );
    std::process::exit(2);
}

fn parse_args() -> Options {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut o = Options {
        seconds: 30.0,
        seed: 13,
        timeout: Duration::from_millis(1000),
        max_alloc: 512 << 20,
        targets: Vec::new(),
        corpus: here.join("corpus"),
        artifacts: here.join("artifacts"),
        replay: None,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut val = || {
            args.next()
                .unwrap_or_else(|| usage(&format!("{a} needs a value")))
        };
        match a.as_str() {
            "--seconds" => o.seconds = val().parse().unwrap_or_else(|_| usage("bad --seconds")),
            "--seed" => o.seed = val().parse().unwrap_or_else(|_| usage("bad --seed")),
            "--timeout-ms" => {
                o.timeout = Duration::from_millis(
                    val().parse().unwrap_or_else(|_| usage("bad --timeout-ms")),
                )
            }
            "--max-alloc-mb" => {
                o.max_alloc = val()
                    .parse::<usize>()
                    .unwrap_or_else(|_| usage("bad --max-alloc-mb"))
                    << 20
            }
            "--target" => o.targets.push(val()),
            "--corpus" => o.corpus = PathBuf::from(val()),
            "--artifacts" => o.artifacts = PathBuf::from(val()),
            "--replay" => o.replay = Some(PathBuf::from(val())),
            "--list" => {
                for (name, _) in TARGETS {
                    println!("{name}");
                }
                std::process::exit(0);
            }
            other => usage(&format!("unknown argument {other}")),
        }
    }
    for t in &o.targets {
        if !TARGETS.iter().any(|(n, _)| n == t) {
            usage(&format!("unknown target {t}"));
        }
    }
    o
}

fn load_corpus(dir: &Path) -> Vec<Vec<u8>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| rd.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    files.sort();
    files
        .iter()
        .filter(|p| p.is_file())
        .filter_map(|p| std::fs::read(p).ok())
        .collect()
}

const TOKENS: &[&[u8]] = &[
    b"nan",
    b"inf",
    b"-inf",
    b"NaN",
    b"1e308",
    b"1e999",
    b"-0",
    b"0",
    b"1e-300",
    b"-1",
    b"18446744073709551615",
    b"9223372036854775807",
    b"4294967296",
    b"\"\"",
    b"[]",
    b"{}",
    b"[[",
    b"]]",
    b"null",
    b"true",
    b"=",
    b".",
    b"\n",
    b"\"",
    b",",
    b"[x]\n",
    b"1e6",
];

fn mutate(rng: &mut ChaCha8Rng, input: &mut Vec<u8>, corpus: &[Vec<u8>]) {
    let rounds = rng.random_range(1..=8);
    for _ in 0..rounds {
        let len = input.len();
        match rng.random_range(0..9u8) {
            0 if len > 0 => {
                let i = rng.random_range(0..len);
                input[i] ^= 1 << rng.random_range(0..8);
            }
            1 if len > 0 => {
                let i = rng.random_range(0..len);
                input[i] = [0u8, 0xff, 0x7f, 0x80, b'9', b'-', b'e', b' '][rng.random_range(0..8)];
            }
            2 => {
                let i = rng.random_range(0..=len);
                let n = rng.random_range(1..=16);
                let bytes: Vec<u8> = (0..n).map(|_| rng.random()).collect();
                input.splice(i..i, bytes);
            }
            3 if len > 0 => {
                let i = rng.random_range(0..len);
                let j = (i + rng.random_range(1..=32)).min(len);
                input.drain(i..j);
            }
            4 if len > 0 => {
                let i = rng.random_range(0..len);
                let j = (i + rng.random_range(1..=64)).min(len);
                let chunk = input[i..j].to_vec();
                let at = rng.random_range(0..=input.len());
                input.splice(at..at, chunk);
            }
            5 => {
                // Replace a number (or insert) with an interesting token.
                let tok = TOKENS[rng.random_range(0..TOKENS.len())];
                let digits: Vec<usize> = (0..len).filter(|&i| input[i].is_ascii_digit()).collect();
                if digits.is_empty() {
                    let at = rng.random_range(0..=len);
                    input.splice(at..at, tok.iter().copied());
                } else {
                    let s = digits[rng.random_range(0..digits.len())];
                    let mut e = s;
                    while e < len && (input[e].is_ascii_digit() || b".eE+-".contains(&input[e])) {
                        e += 1;
                    }
                    input.splice(s..e, tok.iter().copied());
                }
            }
            6 if !corpus.is_empty() => {
                let other = &corpus[rng.random_range(0..corpus.len())];
                if !other.is_empty() {
                    let i = rng.random_range(0..other.len());
                    let j = rng.random_range(i..=other.len());
                    let at = rng.random_range(0..=len);
                    input.splice(at..at, other[i..j].iter().copied());
                }
            }
            7 if len > 0 => input.truncate(rng.random_range(0..len)),
            _ => {
                if len > 0 {
                    let i = rng.random_range(0..len);
                    input[i] = rng.random();
                }
            }
        }
    }
    input.truncate(MAX_INPUT);
}

/// Run one input: `Ok(elapsed)` or `Err(panic message)`.
fn exec(name: &str, f: Target, input: &[u8]) -> Result<Duration, String> {
    if let Ok(mut g) = CURRENT.lock() {
        *g = Some(Current {
            target: name.to_string(),
            input: input.to_vec(),
        });
    }
    STARTED_NS.store(now_ns(), Ordering::SeqCst);
    let t0 = Instant::now();
    let r = panic::catch_unwind(AssertUnwindSafe(|| f(input)));
    let dt = t0.elapsed();
    STARTED_NS.store(0, Ordering::SeqCst);
    match r {
        Ok(()) => Ok(dt),
        Err(_) => Err(LAST_PANIC.lock().map(|s| s.clone()).unwrap_or_default()),
    }
}

#[derive(Default)]
struct Stats {
    execs: u64,
    findings: Vec<String>,
}

/// Run one input and record a finding: a panic, or slower than the limit twice in a row.
fn check(name: &str, f: Target, input: &[u8], timeout: Duration, st: &mut Stats) {
    st.execs += 1;
    match exec(name, f, input) {
        Err(msg) => {
            let path = save(name, "crash", input);
            st.findings
                .push(format!("panic: {msg} ({})", path.display()));
        }
        Ok(dt) if dt > timeout => {
            // Once more: the machine may just have been busy.
            if let Ok(dt2) = exec(name, f, input) {
                if dt2 > timeout {
                    let path = save(name, "slow", input);
                    st.findings.push(format!(
                        "slow: {:.2} s and {:.2} s ({})",
                        dt.as_secs_f64(),
                        dt2.as_secs_f64(),
                        path.display()
                    ));
                }
            }
        }
        Ok(_) => {}
    }
}

fn main() {
    let o = parse_args();
    let _ = ARTIFACTS.set(o.artifacts.clone());
    ALLOC_CAP.store(o.max_alloc, Ordering::SeqCst);
    panic::set_hook(Box::new(|info| {
        if let Ok(mut s) = LAST_PANIC.lock() {
            *s = info.to_string().replace('\n', " ");
        }
    }));
    // Watchdog: an input still running after 10× the limit is a hang.
    let hang = o.timeout * 10;
    std::thread::spawn(move || loop {
        std::thread::sleep(Duration::from_millis(100));
        let s = STARTED_NS.load(Ordering::SeqCst);
        if s != 0 && now_ns().saturating_sub(s) > hang.as_nanos() as u64 {
            REPORTING.store(true, Ordering::SeqCst);
            finding_exit(
                "hang",
                &format!("still running after {:.1} s", hang.as_secs_f64()),
            );
        }
    });

    let selected: Vec<(&str, Target)> = TARGETS
        .iter()
        .filter(|(n, _)| o.targets.is_empty() || o.targets.iter().any(|t| t == n))
        .copied()
        .collect();

    if let Some(file) = &o.replay {
        let input =
            std::fs::read(file).unwrap_or_else(|e| usage(&format!("{}: {e}", file.display())));
        let mut bad = false;
        for (name, f) in &selected {
            match exec(name, *f, &input) {
                Ok(dt) => println!("{name}: ok in {:.3} s", dt.as_secs_f64()),
                Err(msg) => {
                    println!("{name}: PANIC {msg}");
                    bad = true;
                }
            }
        }
        std::process::exit(i32::from(bad));
    }

    let mut total_findings = 0;
    println!(
        "{:<20} {:>9} {:>8} {:>9}  findings (seed {}, {} s per target)",
        "target", "execs", "corpus", "execs/s", o.seed, o.seconds
    );
    for (name, f) in &selected {
        let corpus = load_corpus(&o.corpus.join(name));
        // Seeded by the target's place in the whole list, so that a target draws the same
        // inputs whether it runs alone, with all of them or split over processes.
        let ti = TARGETS.iter().position(|(n, _)| n == name).unwrap_or(0);
        let mut rng = ChaCha8Rng::seed_from_u64(o.seed.wrapping_mul(1000).wrapping_add(ti as u64));
        let mut st = Stats::default();
        let t0 = Instant::now();
        for input in &corpus {
            check(name, *f, input, o.timeout, &mut st);
        }
        let deadline = Duration::from_secs_f64(o.seconds);
        let mut buf = Vec::new();
        while t0.elapsed() < deadline && st.findings.len() < 5 {
            buf.clear();
            if corpus.is_empty() || rng.random_range(0..4u8) == 0 {
                let n = rng.random_range(0..=2048usize);
                buf.resize(n, 0);
                rng.fill_bytes(&mut buf);
            } else {
                buf.extend_from_slice(&corpus[rng.random_range(0..corpus.len())]);
                mutate(&mut rng, &mut buf, &corpus);
            }
            check(name, *f, &buf, o.timeout, &mut st);
        }
        let secs = t0.elapsed().as_secs_f64().max(1e-9);
        println!(
            "{:<20} {:>9} {:>8} {:>9.0}  {}",
            name,
            st.execs,
            corpus.len(),
            st.execs as f64 / secs,
            st.findings.len()
        );
        for fnd in &st.findings {
            println!("    {fnd}");
        }
        total_findings += st.findings.len();
    }
    if total_findings > 0 {
        println!(
            "FAILED: {total_findings} finding(s); inputs saved under {}",
            o.artifacts.display()
        );
        std::process::exit(1);
    }
    println!("fuzz: 0 findings");
}
