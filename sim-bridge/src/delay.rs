//! Fault injection (tests and bench/faults only): a FIFO that holds items for a fixed time.
//!
//! `-p test_cmd_delay_ms` holds every received cmd_vel before the simulator sees it;
//! `-p test_state_delay_ms` holds every outgoing state frame (poses, has_part, part_ready,
//! markers, metrics, /clock) before it is published. The step loop never waits on the
//! queue: it pushes, and drains what is due whenever it wakes (the earliest due time is
//! one of its poll deadlines).

use std::collections::VecDeque;
use std::time::{Duration, Instant};

#[derive(Debug)]
pub struct DelayQueue<T> {
    delay: Duration,
    q: VecDeque<(Instant, T)>,
}

impl<T> DelayQueue<T> {
    /// Items are released `delay_ms` after they are pushed (0: the queue is bypassed by
    /// callers, see [`DelayQueue::is_active`]).
    pub fn new(delay_ms: f64) -> Self {
        Self {
            delay: Duration::from_secs_f64(delay_ms.max(0.0) / 1000.0),
            q: VecDeque::new(),
        }
    }

    /// Whether items must go through the queue (a nonzero delay).
    pub fn is_active(&self) -> bool {
        !self.delay.is_zero()
    }

    /// Hold `item`, pushed at `now`, until `now + delay`.
    pub fn push(&mut self, now: Instant, item: T) {
        // the delay is constant, so due times are non-decreasing as long as `now` is
        self.q.push_back((now + self.delay, item));
    }

    /// When the oldest held item is due.
    pub fn next_due(&self) -> Option<Instant> {
        self.q.front().map(|(due, _)| *due)
    }

    /// The oldest item if it is due at `now`.
    pub fn pop_due(&mut self, now: Instant) -> Option<T> {
        if self.q.front().is_some_and(|(due, _)| *due <= now) {
            self.q.pop_front().map(|(_, x)| x)
        } else {
            None
        }
    }

    pub fn len(&self) -> usize {
        self.q.len()
    }

    pub fn is_empty(&self) -> bool {
        self.q.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holds_items_for_the_delay_and_keeps_their_order() {
        let t0 = Instant::now();
        let ms = |x: u64| t0 + Duration::from_millis(x);
        let mut q = DelayQueue::new(200.0);
        assert!(q.is_active());
        q.push(ms(0), 'a');
        q.push(ms(100), 'b');
        q.push(ms(100), 'c');
        assert_eq!(q.len(), 3);
        assert_eq!(q.next_due(), Some(ms(200)));
        assert_eq!(q.pop_due(ms(199)), None);
        assert_eq!(q.pop_due(ms(200)), Some('a'));
        assert_eq!(q.pop_due(ms(250)), None);
        assert_eq!(q.next_due(), Some(ms(300)));
        assert_eq!(q.pop_due(ms(400)), Some('b'));
        assert_eq!(q.pop_due(ms(400)), Some('c'));
        assert_eq!(q.pop_due(ms(10_000)), None);
        assert!(q.is_empty());
        assert_eq!(q.next_due(), None);
    }

    #[test]
    fn zero_delay_is_inactive() {
        let q: DelayQueue<u8> = DelayQueue::new(0.0);
        assert!(!q.is_active());
    }
}
