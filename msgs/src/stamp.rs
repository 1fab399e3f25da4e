//! Stamp keys: how the lockstep protocol (docs/adr/0003-lockstep.md) compares the
//! simulator step a sample belongs to, whether it came as a header stamp or as the DDS
//! source timestamp (`ros::stamp_key_info`).

/// Stamps are compared in whole microseconds: RTPS timestamps have a 2^-32 s tick, so a
/// nanosecond value does not survive the round trip exactly.
pub fn stamp_key_ns(ns: i64) -> i64 {
    (ns + 500).div_euclid(1000)
}

/// The stamp key of a `builtin_interfaces/Time`.
pub fn stamp_key_time(t: &crate::Time) -> i64 {
    stamp_key_ns(t.sec as i64 * 1_000_000_000 + t.nanosec as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamp_keys_tolerate_tick_rounding() {
        assert_eq!(stamp_key_ns(100_000_000), stamp_key_ns(99_999_999));
        assert_eq!(stamp_key_ns(100_000_000), stamp_key_ns(100_000_001));
        assert_ne!(stamp_key_ns(100_000_000), stamp_key_ns(200_000_000));
        let t = crate::Time::from_secs_f64(0.3);
        assert_eq!(stamp_key_time(&t), 300_000);
    }
}
