//! The tracking log: what was played and what was measured.
//!
//! CSV with the header `t_s,gradient_t_per_m,x1_m,...,xM_m`, one row per
//! time, times strictly increasing; `gradient_t_per_m` is the gradient
//! played from that time until the next row's (the last row's plays for no
//! time); `xi_m` is capsule i's measured position at that time, or empty
//! where it was not measured. The project's own run JSON (`simulate
//! --json`) is read too: its measurements and the played gradient.

use serde::Deserialize;

/// A log, checked: times increasing, every value finite.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackingLog {
    /// Row times, s.
    pub t_s: Vec<f64>,
    /// Gradient from each row's time to the next row's, T/m.
    pub gradient_t_per_m: Vec<f64>,
    /// Per row, per capsule: the measured position, m (None: not measured).
    pub positions_m: Vec<Vec<Option<f64>>>,
}

/// Why a log is refused: where (1-based line and column, 0 when the file
/// as a whole) and what.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}, column {column}: {message}")]
pub struct LogError {
    pub line: usize,
    pub column: usize,
    pub message: String,
}

fn err(line: usize, column: usize, message: impl Into<String>) -> LogError {
    LogError {
        line,
        column,
        message: message.into(),
    }
}

impl TrackingLog {
    /// Number of capsules.
    pub fn capsule_count(&self) -> usize {
        self.positions_m.first().map_or(0, Vec::len)
    }

    /// Measurements of capsule `i`: (row, position).
    pub fn measurements(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.positions_m
            .iter()
            .enumerate()
            .filter_map(move |(r, p)| p.get(i).copied().flatten().map(|x| (r, x)))
    }

    /// Reads the CSV format for `capsules` capsules; every capsule needs at
    /// least `min_measurements` positions.
    pub fn from_csv(
        text: &str,
        capsules: usize,
        min_measurements: usize,
    ) -> Result<TrackingLog, LogError> {
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        let Some((h, header)) = lines.next() else {
            return Err(err(
                1,
                0,
                "empty log: expected the header t_s,gradient_t_per_m,x1_m,...",
            ));
        };
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        let mut expected = vec!["t_s".to_string(), "gradient_t_per_m".to_string()];
        expected.extend((1..=capsules).map(|i| format!("x{i}_m")));
        for (c, want) in expected.iter().enumerate() {
            match names.get(c) {
                Some(n) if n == want => {}
                Some(n) => {
                    return Err(err(
                        h + 1,
                        c + 1,
                        format!("column `{n}`, expected `{want}`"),
                    ))
                }
                None => return Err(err(h + 1, c + 1, format!("missing column `{want}`"))),
            }
        }
        if names.len() > expected.len() {
            return Err(err(
                h + 1,
                expected.len() + 1,
                format!(
                    "unexpected column `{}`: the config has {capsules} capsules",
                    names[expected.len()]
                ),
            ));
        }
        let mut log = TrackingLog {
            t_s: Vec::new(),
            gradient_t_per_m: Vec::new(),
            positions_m: Vec::new(),
        };
        for (l, line) in lines {
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            if fields.len() != expected.len() {
                return Err(err(
                    l + 1,
                    fields.len().min(expected.len()) + 1,
                    format!("{} fields, expected {}", fields.len(), expected.len()),
                ));
            }
            let number = |c: usize, what: &str| -> Result<f64, LogError> {
                let v: f64 = fields[c].parse().map_err(|_| {
                    err(
                        l + 1,
                        c + 1,
                        format!("{what} `{}` is not a number", fields[c]),
                    )
                })?;
                if !v.is_finite() {
                    return Err(err(l + 1, c + 1, format!("{what} {v} is not finite")));
                }
                Ok(v)
            };
            let t = number(0, "time")?;
            if let Some(&prev) = log.t_s.last() {
                if t <= prev {
                    return Err(err(
                        l + 1,
                        1,
                        format!("time {t} s does not follow {prev} s"),
                    ));
                }
            }
            let u = number(1, "gradient")?;
            let mut row = Vec::with_capacity(capsules);
            for (c, field) in fields.iter().enumerate().skip(2) {
                row.push(if field.is_empty() {
                    None
                } else {
                    Some(number(c, "position")?)
                });
            }
            log.t_s.push(t);
            log.gradient_t_per_m.push(u);
            log.positions_m.push(row);
        }
        log.check_counts(capsules, min_measurements)?;
        Ok(log)
    }

    /// Reads the project's run JSON (`simulate --json`): the played
    /// gradient per record and the measurements the controller received.
    pub fn from_run_json(
        text: &str,
        capsules: usize,
        min_measurements: usize,
    ) -> Result<TrackingLog, LogError> {
        #[derive(Deserialize)]
        struct Measurement {
            t_s: f64,
            positions_m: Vec<f64>,
            #[serde(default)]
            lost: bool,
        }
        #[derive(Deserialize)]
        struct Run {
            t: Vec<f64>,
            u: Vec<f64>,
            measurements: Vec<Measurement>,
        }
        let run: Run = serde_json::from_str(text)
            .map_err(|e| err(e.line(), e.column(), format!("run JSON: {e}")))?;
        if run.t.len() != run.u.len() {
            return Err(err(
                0,
                0,
                format!(
                    "run JSON: {} times but {} gradients",
                    run.t.len(),
                    run.u.len()
                ),
            ));
        }
        // Rows: every record time, with the measurements at their times.
        let mut rows: Vec<(f64, f64, Vec<Option<f64>>)> = run
            .t
            .iter()
            .zip(&run.u)
            .map(|(&t, &u)| (t, u, vec![None; capsules]))
            .collect();
        for m in run.measurements.iter().filter(|m| !m.lost) {
            if m.positions_m.len() != capsules {
                return Err(err(
                    0,
                    0,
                    format!(
                        "run JSON: a measurement has {} positions, expected {capsules}",
                        m.positions_m.len()
                    ),
                ));
            }
            match rows.iter().position(|r| (r.0 - m.t_s).abs() < 1e-9) {
                Some(k) => rows[k].2 = m.positions_m.iter().map(|&p| Some(p)).collect(),
                None => {
                    return Err(err(
                        0,
                        0,
                        format!(
                            "run JSON: measurement at {} s matches no record time",
                            m.t_s
                        ),
                    ))
                }
            }
        }
        let mut log = TrackingLog {
            t_s: Vec::new(),
            gradient_t_per_m: Vec::new(),
            positions_m: Vec::new(),
        };
        for (t, u, p) in rows {
            if !(t.is_finite() && u.is_finite()) || p.iter().flatten().any(|x| !x.is_finite()) {
                return Err(err(0, 0, format!("run JSON: non-finite value at {t} s")));
            }
            if log.t_s.last().is_some_and(|&prev| t <= prev) {
                // Records at the same instant (a zero-length phase): keep the first.
                continue;
            }
            log.t_s.push(t);
            log.gradient_t_per_m.push(u);
            log.positions_m.push(p);
        }
        log.check_counts(capsules, min_measurements)?;
        Ok(log)
    }

    fn check_counts(&self, capsules: usize, min_measurements: usize) -> Result<(), LogError> {
        for i in 0..capsules {
            let n = self.measurements(i).count();
            if n < min_measurements {
                return Err(err(
                    0,
                    3 + i,
                    format!(
                        "capsule {} has {n} measurements, at least {min_measurements} needed",
                        i + 1
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The log as CSV (the documented format).
    pub fn to_csv(&self) -> String {
        let m = self.capsule_count();
        let mut out = String::from("t_s,gradient_t_per_m");
        for i in 1..=m {
            out.push_str(&format!(",x{i}_m"));
        }
        out.push('\n');
        for ((t, u), p) in self
            .t_s
            .iter()
            .zip(&self.gradient_t_per_m)
            .zip(&self.positions_m)
        {
            out.push_str(&format!("{t:?},{u:?}"));
            for x in p {
                match x {
                    Some(x) => out.push_str(&format!(",{x:?}")),
                    None => out.push(','),
                }
            }
            out.push('\n');
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_documented_format() {
        let text =
            "t_s,gradient_t_per_m,x1_m,x2_m\n0,0,0.001,0.002\n0.02,0.04,,\n0.04,0,0.0011,0.0021\n";
        let log = TrackingLog::from_csv(text, 2, 2).unwrap();
        assert_eq!(log.t_s, vec![0.0, 0.02, 0.04]);
        assert_eq!(log.positions_m[1], vec![None, None]);
        assert_eq!(log.measurements(1).count(), 2);
        assert_eq!(TrackingLog::from_csv(&log.to_csv(), 2, 2).unwrap(), log);
    }

    #[test]
    fn malformed_logs_name_line_and_column() {
        let cases = [
            ("", "line 1, column 0: empty log"),
            (
                "t_s,gradient_t_per_m,x1_m\n",
                "line 1, column 4: missing column `x2_m`",
            ),
            (
                "t_s,u,x1_m,x2_m\n",
                "line 1, column 2: column `u`, expected `gradient_t_per_m`",
            ),
            (
                "t_s,gradient_t_per_m,x1_m,x2_m\n0,0,0,0\n0.02,abc,,\n",
                "line 3, column 2: gradient `abc` is not a number",
            ),
            (
                "t_s,gradient_t_per_m,x1_m,x2_m\n0,0,0,0\n0,0,,\n",
                "line 3, column 1: time 0 s does not follow 0 s",
            ),
            (
                "t_s,gradient_t_per_m,x1_m,x2_m\n0,0,0,0\n0.02,0,NaN,\n",
                "line 3, column 3: position NaN is not finite",
            ),
            (
                "t_s,gradient_t_per_m,x1_m,x2_m\n0,0,0\n",
                "line 2, column 4: 3 fields, expected 4",
            ),
            (
                "t_s,gradient_t_per_m,x1_m,x2_m\n0,0,0,0\n",
                "capsule 1 has 1 measurements, at least 2 needed",
            ),
        ];
        for (text, needle) in cases {
            let e = TrackingLog::from_csv(text, 2, 2).unwrap_err().to_string();
            assert!(e.contains(needle), "{e:?} lacks {needle:?}");
        }
    }
}
