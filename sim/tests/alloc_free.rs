//! The step loop (step + every robot's observation) allocates nothing once warmed up.
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

// Only allocations made by the measuring thread count: the test harness's own threads
// allocate at any time.
thread_local! {
    static MEASURING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn count() {
    if MEASURING.try_with(|m| m.get()).unwrap_or(false) {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn step_and_observe_do_not_allocate() {
    for setup in ["14.10_4", "100.16_2"] {
        let mut env =
            sim::Env::new(sim::ScenarioConfig::default(), setup.parse().unwrap(), 3).unwrap();
        let n = env.n_robots();
        let mut obs = obs::ObsBatch::default();
        let acts: Vec<Vec<u8>> = (0..5u8).map(|a| vec![a; n]).collect();
        for a in &acts {
            env.step_actions(a).unwrap();
            env.observe(&mut obs);
        }
        MEASURING.with(|m| m.set(true));
        let before = ALLOCS.load(Ordering::SeqCst);
        for k in 0..150 {
            env.step_actions(&acts[(k * 7 + 3) % 5]).unwrap();
            env.observe(&mut obs);
        }
        let after = ALLOCS.load(Ordering::SeqCst);
        MEASURING.with(|m| m.set(false));
        assert_eq!(
            after - before,
            0,
            "{setup}: {} allocations in 150 steps",
            after - before
        );
    }
}
