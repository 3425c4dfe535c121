//! Capability and gauge studies as a terminal table or CSV (JSON is their serde form).

use super::CharacteristicStudy;
use super::study::GaugeItem;
use crate::core::capability::{Index, Indices};
use std::fmt::Write as _;

fn num(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

fn index(i: Option<Index>) -> String {
    i.map_or("-".into(), |i| {
        format!("{:.2} ({:.2})", i.value, i.lower_95)
    })
}

/// One line per characteristic, then the notes: methods, missing limits and indices. Under
/// the title, a line marking the figures indicative when the window is too small.
pub(crate) fn capability_table(title: &str, items: &[CharacteristicStudy]) -> String {
    let mut s = format!("{title}\n");
    if let Some(why) = super::indicative_reason(items) {
        let _ = writeln!(s, "indicative only: {why}");
    }
    let _ = writeln!(
        s,
        "{:<14} {:>4} {:>4} {:>9} {:>8} {:>8} {:>8} {:>8}  {:<14} {:>12} {:>12} {:>12} {:>12} {:>10} {:>7}",
        "characteristic",
        "unit",
        "n",
        "mean",
        "σ within",
        "σ overal",
        "LSL",
        "USL",
        "model",
        "Cp (95%)",
        "Cpk (95%)",
        "Pp (95%)",
        "Ppk (95%)",
        "exp. ppm",
        "obs. %"
    );
    let mut notes = Vec::new();
    for it in items {
        let name = it.characteristic.as_str();
        let d = if it.unit == "°" { 4 } else { 3 };
        let Some(c) = &it.capability else {
            let _ = writeln!(s, "{name:<14} {:>4}  no statistics", it.unit);
            notes.extend(it.note.as_ref().map(|n| format!("{name}: {n}")));
            continue;
        };
        let ix: Option<&Indices> = c.indices.as_ref();
        let _ = writeln!(
            s,
            "{name:<14} {:>4} {:>4} {:>9} {:>8} {:>8} {:>8} {:>8}  {:<14} {:>12} {:>12} {:>12} {:>12} {:>10} {:>7}",
            it.unit,
            c.n,
            num(Some(c.mean), d),
            num(Some(c.sigma_within), d),
            num(Some(c.sigma_overall), d),
            num(c.limits.lower, d),
            num(c.limits.upper, d),
            c.model.name(),
            index(ix.and_then(|i| i.cp)),
            index(ix.map(|i| i.cpk)),
            index(ix.and_then(|i| i.pp)),
            index(ix.map(|i| i.ppk)),
            num(ix.map(|i| i.expected_share_out * 1e6), 1),
            num(ix.map(|i| i.observed_share_out * 100.0), 1),
        );
        notes.extend(it.note.as_ref().map(|n| format!("{name}: {n}")));
    }
    s.push_str(
        "\nσ within: mean moving range / d2 (1.128); σ overall: n − 1. Two-sided: ISO 22514-2 model A1\n\
         (normal). Bounded at zero (max_error, profile_error, roundness): model A2, the likeliest of folded\n\
         normal, log-normal, Weibull; percentile method, Cpk = Cpu, Ppk = Ppu. Bounds (95 %, lower):\n\
         chi-square for Cp/Pp, Bissell for Cpk/Ppk.\n",
    );
    for n in notes {
        let _ = writeln!(s, "{n}");
    }
    s
}

/// The same as CSV, one row per characteristic.
pub(crate) fn capability_csv(
    machine: &str,
    feature: &str,
    items: &[CharacteristicStudy],
) -> String {
    let mut s = String::from(
        "machine,feature,characteristic,unit,n,mean,sigma_within,sigma_overall,lower_limit,upper_limit,model,cp,cp_lower_95,cpk,cpk_lower_95,pp,pp_lower_95,ppk,ppk_lower_95,expected_share_out,observed_share_out,note\n",
    );
    for it in items {
        let c = it.capability.as_ref();
        let ix = c.and_then(|c| c.indices.as_ref());
        let f = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
        let pair =
            |i: Option<Index>| format!("{},{}", f(i.map(|i| i.value)), f(i.map(|i| i.lower_95)));
        let _ = writeln!(
            s,
            "{machine},{feature},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},\"{}\"",
            it.characteristic.as_str(),
            it.unit,
            c.map_or(String::new(), |c| c.n.to_string()),
            f(c.map(|c| c.mean)),
            f(c.map(|c| c.sigma_within)),
            f(c.map(|c| c.sigma_overall)),
            f(it.limits.limits.lower),
            f(it.limits.limits.upper),
            c.map_or("", |c| c.model.name()),
            pair(ix.and_then(|i| i.cp)),
            pair(ix.map(|i| i.cpk)),
            pair(ix.and_then(|i| i.pp)),
            pair(ix.map(|i| i.ppk)),
            f(ix.map(|i| i.expected_share_out)),
            f(ix.map(|i| i.observed_share_out)),
            it.note.as_deref().unwrap_or("").replace('"', "\"\""),
        );
    }
    s
}

/// The gauge study as a table.
pub(crate) fn gauge_table(title: &str, items: &[GaugeItem]) -> String {
    let mut s = format!("{title}\n");
    let _ = writeln!(
        s,
        "{:<14} {:>4} {:>4} {:>10} {:>10} {:>10} {:>9} {:>6} {:>6}  verdict",
        "characteristic", "unit", "n", "T", "bias", "s", "bias t", "Cg", "Cgk"
    );
    for it in items {
        let name = it.characteristic.as_str();
        match &it.study {
            Some(g) => {
                let _ = writeln!(
                    s,
                    "{name:<14} {:>4} {:>4} {:>10.4} {:>10.4} {:>10.4} {:>9.2} {:>6.2} {:>6.2}  {}{}",
                    it.unit,
                    g.n,
                    g.tolerance,
                    g.bias,
                    g.sigma,
                    g.bias_t,
                    g.cg,
                    g.cgk,
                    if g.capable { "capable" } else { "NOT capable" },
                    if g.bias_significant {
                        ", bias significant"
                    } else {
                        ""
                    },
                );
            }
            None => {
                let _ = writeln!(s, "{name:<14} {:>4}  no study", it.unit);
            }
        }
    }
    s.push_str(
        "\nType-1 study (VDA 5 / AIAG MSA): reference 0 (the master is the nominal), 20 % of the tolerance\n\
         over 6 s: Cg = 0.2·T/6s, Cgk = (0.1·T − |bias|)/3s; capable when both ≥ 1.33. Bias tested\n\
         with Student's t at 5 %.\n",
    );
    for it in items {
        if let Some(n) = &it.note {
            let _ = writeln!(s, "{}: {n}", it.characteristic.as_str());
        }
    }
    s
}
