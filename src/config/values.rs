//! Range and sense checks of single sections' values (each gauge), each
//! problem with the line of its key.

use super::{ConfigProblem, GaugeSection};

impl GaugeSection {
    /// A drop gauge's `stable_ms` and `max_file_bytes`, as the drop folder takes them;
    /// `None` for other gauges.
    pub(crate) fn drop_options(&self) -> Option<crate::gauge::DropOptions> {
        match self {
            GaugeSection::Drop {
                stable_ms,
                max_file_bytes,
                ..
            } => Some(crate::gauge::DropOptions {
                stable_ms: *stable_ms,
                max_file_bytes: *max_file_bytes,
            }),
            _ => None,
        }
    }

    /// `line` gives the line of a key below the gauge section (`""` for the section).
    pub(super) fn problems(
        &self,
        label: &str,
        line: impl Fn(&str) -> Option<usize>,
    ) -> Vec<ConfigProblem> {
        let mut p = Vec::new();
        let range = |p: &mut Vec<ConfigProblem>,
                     key: &str,
                     value: u64,
                     ok: std::ops::RangeInclusive<u64>| {
            if !ok.contains(&value) {
                p.push(ConfigProblem::at(
                    line(&format!(".{key}")),
                    format!(
                        "{label}.gauge.{key} = {value}: must be {} to {}",
                        ok.start(),
                        ok.end()
                    ),
                ));
            }
        };
        match self {
            GaugeSection::Sim {
                part_interval_ms,
                grinder,
                ..
            } => {
                range(
                    &mut p,
                    "part_interval_ms",
                    *part_interval_ms,
                    1..=86_400_000,
                );
                p.extend(grinder.problems().into_iter().map(|e| {
                    ConfigProblem::at(line(".grinder"), format!("{label}.gauge.grinder: {e}"))
                }));
            }
            GaugeSection::Drop {
                poll_ms,
                stable_ms,
                max_file_bytes,
                ..
            } => {
                range(&mut p, "poll_ms", *poll_ms, 10..=60_000);
                range(&mut p, "stable_ms", *stable_ms, 1..=3_600_000);
                range(&mut p, "max_file_bytes", *max_file_bytes, 1024..=(1 << 30));
            }
            GaugeSection::Can { interface, .. } if interface.is_empty() => {
                p.push(ConfigProblem::at(
                    line(".interface"),
                    format!("{label}.gauge.interface: must not be empty"),
                ));
            }
            GaugeSection::Serial { port, baud } => {
                if port.is_empty() {
                    p.push(ConfigProblem::at(
                        line(".port"),
                        format!("{label}.gauge.port: must not be empty"),
                    ));
                }
                range(&mut p, "baud", u64::from(*baud), 50..=4_000_000);
            }
            GaugeSection::Can { .. } => {}
        }
        p
    }
}
