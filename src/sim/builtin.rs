//! Built-in scenarios, embedded in the binary from `scenarios/*.toml`.

/// (name, one-line description, TOML text).
pub const BUILTIN: &[(&str, &str, &str)] = &[
    (
        "default",
        "Seed 004 comparison at a few rates (centralized KF, Algorithms 1 and 2), 100 trials",
        include_str!("../../scenarios/default.toml"),
    ),
    (
        "dormann-fig1",
        "Seed 004 Fig. 1: MSE and trace against the communication rate, 500 runs x 100 steps",
        include_str!("../../scenarios/dormann-fig1.toml"),
    ),
    (
        "zheng-fig1",
        "Seed 000 Fig. 1: censoring with feedback, N = 2, l = 1, 5000 trials, 1000 particles",
        include_str!("../../scenarios/zheng-fig1.toml"),
    ),
    (
        "zhang-fig4",
        "Seed 003 Fig. 4: quantized-innovation fusion at 1 payload bit, 50 range sensors, 1000 runs",
        include_str!("../../scenarios/zhang-fig4.toml"),
    ),
    (
        "zhang-fig5",
        "Seed 003 Fig. 5: quantized-innovation fusion at 2 payload bits, 50 range sensors, 1000 runs",
        include_str!("../../scenarios/zhang-fig5.toml"),
    ),
    (
        "zhang-table7",
        "Seed 003 Table 7: covariance-correction coefficient rho of every quantizer (computed)",
        include_str!("../../scenarios/zhang-table7.toml"),
    ),
    (
        "zhang-tables",
        "Seed 003 Tables 1-6: quantization levels against payload bits (computed)",
        include_str!("../../scenarios/zhang-tables.toml"),
    ),
];

/// The TOML text of a built-in scenario.
pub fn get(name: &str) -> Option<&'static str> {
    BUILTIN
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|(_, _, t)| *t)
}
