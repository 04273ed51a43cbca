//! Unit tests of the calibrator.
use super::*;

#[test]
fn short_drops_trailing_zeros_and_writes_huge_values_with_an_exponent() {
    assert_eq!(short(24.0), "24");
    assert_eq!(short(12.5), "12.5");
    assert_eq!(short(0.123456), "0.1235");
    assert_eq!(short(999_999_999.0), "999999999");
    assert_eq!(short(1e9), "1e9");
    assert_eq!(short(1e300), "1e300");
    assert_eq!(short(1.23456789e12), "1.2346e12");
    assert_eq!(bits_cell(384.0), "384.0");
    assert_eq!(bits_cell(1e300), "1e300");
}

#[test]
fn directory_labels_read_back_as_their_budget() {
    for v in [
        24.0,
        12.5,
        24.00001,
        24.00004,
        1e9,
        5e9,
        1.23456789e12,
        1e300,
        2e-300,
    ] {
        let label = dir_label(v);
        assert_eq!(label.parse::<f64>(), Ok(v), "{v}: {label}");
    }
}
