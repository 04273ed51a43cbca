//! Built-in scenarios, embedded in the binary from `scenarios/*.toml`.

/// (name, one-line description, TOML text).
pub const BUILTIN: &[(&str, &str, &str)] = &[
    (
        "default",
        "Dormann et al. comparison at a few rates (centralized KF, Algorithms 1 and 2), 100 trials",
        include_str!("../../scenarios/default.toml"),
    ),
    (
        "dormann-fig1",
        "Dormann et al., Fig. 1: MSE and trace against the communication rate, 500 runs x 100 steps",
        include_str!("../../scenarios/dormann-fig1.toml"),
    ),
    (
        "zheng-fig1",
        "Zheng et al. (2014), Fig. 1: censoring with feedback, N = 2, l = 1, 5000 trials, 1000 particles",
        include_str!("../../scenarios/zheng-fig1.toml"),
    ),
    (
        "zheng-fig2-table1",
        "Zheng et al. (2014), Fig. 2 / Table I: N = 4, l in {1, 1.2, 1.5, 2, 3}, CFwMD vs CFwMD2, transmissions vs Table I",
        include_str!("../../scenarios/zheng-fig2-table1.toml"),
    ),
    (
        "zheng-fig3",
        "Zheng et al. (2014), Fig. 3: non-feedback, N = 2, l = 1 (Prop. 3)",
        include_str!("../../scenarios/zheng-fig3.toml"),
    ),
    (
        "zheng-fig4",
        "Zheng et al. (2014), Fig. 4: vector observations with feedback, N = 2, l = 1",
        include_str!("../../scenarios/zheng-fig4.toml"),
    ),
    (
        "zheng-fig5-table2",
        "Zheng et al. (2014), Fig. 5 / Table II: vector observations, N = 4, CFwMD vs CFwMD2",
        include_str!("../../scenarios/zheng-fig5-table2.toml"),
    ),
    (
        "zheng-fig6",
        "Zheng et al. (2014), Fig. 6: vector observations without feedback (Prop. 6)",
        include_str!("../../scenarios/zheng-fig6.toml"),
    ),
    (
        "zheng-fig8",
        "Zheng et al. (2014), Fig. 8: 9 RSS sensors, l = 2, 10^4 particles, 200 trials",
        include_str!("../../scenarios/zheng-fig8.toml"),
    ),
    (
        "zheng-fig9",
        "Zheng et al. (2014), Fig. 9: RSS sensors, RMSE against l",
        include_str!("../../scenarios/zheng-fig9.toml"),
    ),
    (
        "zheng-fig10-table3",
        "Zheng et al. (2014), Fig. 10 / Table III: RSS sensors, CFwMD vs CFwMD2 for l in {2, 4, 6}",
        include_str!("../../scenarios/zheng-fig10-table3.toml"),
    ),
    (
        "zheng-nofb-n4",
        "Beyond Zheng et al. (2014): non-feedback N = 4, l in {1, 2}, with CFwMD-exact",
        include_str!("../../scenarios/zheng-nofb-n4.toml"),
    ),
    (
        "zhang-fig4",
        "Zhang et al. (2016), Fig. 4: quantized-innovation fusion at 1 payload bit, 50 range sensors, 1000 runs",
        include_str!("../../scenarios/zhang-fig4.toml"),
    ),
    (
        "zhang-fig5",
        "Zhang et al. (2016), Fig. 5: quantized-innovation fusion at 2 payload bits, 50 range sensors, 1000 runs",
        include_str!("../../scenarios/zhang-fig5.toml"),
    ),
    (
        "zhang-table7",
        "Zhang et al. (2016), Table 7: covariance-correction coefficient rho of every quantizer (computed)",
        include_str!("../../scenarios/zhang-table7.toml"),
    ),
    (
        "zhang-tables",
        "Zhang et al. (2016), Tables 1-6: quantization levels against payload bits (computed)",
        include_str!("../../scenarios/zhang-tables.toml"),
    ),
    (
        "geng-oscillator",
        "Geng et al., Section IV-A / Tables II-III: federated Tobit KF, round-robin, censoring regions and noise variances, information bound",
        include_str!("../../scenarios/geng-oscillator.toml"),
    ),
    (
        "geng-tracking",
        "Geng et al., Section IV-B / Figs. 10-11: target tracking with acceleration bias, FTKF-DB vs FTKF",
        include_str!("../../scenarios/geng-tracking.toml"),
    ),
    (
        "sinopoli-critical",
        "Sinopoli et al. (2004): scalar Kalman filter with intermittent observations, arrival rate swept across the critical 1 - 1/a^2, against the bounds and an independent recursion",
        include_str!("../../scenarios/sinopoli-critical.toml"),
    ),
    (
        "gilbert-elliott-stability",
        "Huang and Dey (2007), scalar: Kalman filter over Gilbert-Elliott bursts, p_bg swept across the critical 1 - 1/a^2",
        include_str!("../../scenarios/gilbert-elliott-stability.toml"),
    ),
    (
        "classic-quantized-kf",
        "Ribeiro et al. (2006) and Msechu et al. (2008): the 2/π factor of the sign-of-innovation KF and the c = 1 - D factors of 2-4 bit quantized innovations, against an independent recursion",
        include_str!("../../scenarios/classic-quantized-kf.toml"),
    ),
    (
        "classic-one-bit-static",
        "Ribeiro et al. (2006): one sign bit per measurement of a constant, the 2/π Fisher-information loss (MSE ratio to the all-data KF tends to π/2)",
        include_str!("../../scenarios/classic-one-bit-static.toml"),
    ),
    (
        "classic-one-bit-tracking",
        "Stein et al. (2015): one sign bit per step tracking a slow random walk, MSE ratio to the all-data KF √(π/2) (Ribeiro et al.'s 2/π)",
        include_str!("../../scenarios/classic-one-bit-tracking.toml"),
    ),
    (
        "mesh-line",
        "Multi-hop line: arena-1d's sensors 2 to 5 hops from the sink, every hop lossy and paid; energy and error against hops",
        include_str!("../../scenarios/mesh-line.toml"),
    ),
    (
        "mesh-grid",
        "Multi-hop grid: 16 range sensors and 2 relays to a corner sink, every hop paid; the energy hole on the network map",
        include_str!("../../scenarios/mesh-grid.toml"),
    ),
    (
        "arena-graph",
        "Arena on a graph: a ring of 20 nodes, sink schemes relayed hop by hop beside consensus, diffusion and peer-to-peer fusion at every node (each node's numbers in summary.json)",
        include_str!("../../scenarios/arena-graph.toml"),
    ),
    (
        "arena-graph-rgg",
        "Arena on a random geometric graph: 29 sensors and the sink within 30 m of each other in a 100 m square, the sink schemes (estimate sent back) beside the decentralized ones",
        include_str!("../../scenarios/arena-graph-rgg.toml"),
    ),
    (
        "consensus-energy-ring",
        "Consensus on information to 1e-3 (L = 209) against the all-data KF's convergecast and broadcast back on a ring of 20: network energy a step, checked against an independent count",
        include_str!("../../scenarios/consensus-energy-ring.toml"),
    ),
    (
        "et-ddf-tree",
        "et-ddf at small scale: 30 agents in a tree, absolute sensors on 4; MSE and messages against the trigger (scripts/et-ddf-study.sh adds the drop probability)",
        include_str!("../../scenarios/et-ddf-tree.toml"),
    ),
    (
        "arena-1d",
        "Arena: 1-D constant velocity, 4 scalar linear sensors, every scheme of the registry (--budget, --budgets)",
        include_str!("../../scenarios/arena-1d.toml"),
    ),
    (
        "arena-nca",
        "Arena: Dormann et al.'s six 2-D linear sensors, every scheme that applies",
        include_str!("../../scenarios/arena-nca.toml"),
    ),
    (
        "arena-rss",
        "Arena: Zheng et al.'s (2014) nine RSS sensors, every scheme that applies",
        include_str!("../../scenarios/arena-rss.toml"),
    ),
    (
        "arena-wsn",
        "Arena: Zhang et al.'s (2016) 50 range sensors (quantized innovation activates 3), every scheme that applies",
        include_str!("../../scenarios/arena-wsn.toml"),
    ),
    (
        "arena-tobit",
        "Arena: Geng et al.'s oscillator with bias, two scalar sensors, every scheme that applies",
        include_str!("../../scenarios/arena-tobit.toml"),
    ),
];

/// The TOML text of a built-in scenario.
pub fn get(name: &str) -> Option<&'static str> {
    BUILTIN
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|(_, _, t)| *t)
}

/// A scenario's text and source name from a path, a built-in name, or (when `allow_text`)
/// TOML text itself (anything with a newline or `=` that is not a path of an existing file),
/// with the command line's messages.
pub fn resolve(scenario: &str, allow_text: bool) -> Result<(String, String), String> {
    let path = std::path::Path::new(scenario);
    let text_like = allow_text && (scenario.contains('\n') || scenario.contains('='));
    if text_like && !path.exists() {
        Ok((scenario.to_string(), "<scenario text>".to_string()))
    } else if path.exists() || scenario.ends_with(".toml") {
        let text =
            std::fs::read_to_string(path).map_err(|e| format!("{scenario}: cannot read: {e}"))?;
        Ok((text, scenario.to_string()))
    } else if let Some(t) = get(scenario) {
        Ok((t.to_string(), format!("built-in:{scenario}")))
    } else {
        Err(format!(
            "{scenario:?} is neither a file nor a built-in scenario (`hushfuse list`)"
        ))
    }
}
