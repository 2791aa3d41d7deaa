//! Plain-text tables and number formatting for reports.

use hostas::vk;

/// A table printed with aligned columns: text left-aligned, numbers right-aligned.
#[derive(Clone, Debug, Default)]
pub struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    pub fn new<S: Into<String>>(header: impl IntoIterator<Item = S>) -> Table {
        Table {
            header: header.into_iter().map(Into::into).collect(),
            rows: Vec::new(),
        }
    }
    pub fn row<S: Into<String>>(&mut self, cells: impl IntoIterator<Item = S>) {
        self.rows.push(cells.into_iter().map(Into::into).collect());
    }
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    pub fn render(&self) -> String {
        let cols = self
            .header
            .len()
            .max(self.rows.iter().map(Vec::len).max().unwrap_or(0));
        let mut width = vec![0usize; cols];
        for r in std::iter::once(&self.header).chain(&self.rows) {
            for (i, c) in r.iter().enumerate() {
                width[i] = width[i].max(c.chars().count());
            }
        }
        let numeric = |s: &str| {
            let s = s.trim_end_matches(['%', 'x']);
            !s.is_empty()
                && s.chars()
                    .all(|c| c.is_ascii_digit() || ".,-+e ".contains(c))
                && s.chars().any(|c| c.is_ascii_digit())
        };
        let mut out = String::new();
        let line = |out: &mut String, r: &[String]| {
            let mut s = String::new();
            for (i, w) in width.iter().enumerate() {
                let c = r.get(i).map(String::as_str).unwrap_or("");
                let pad = w - c.chars().count();
                if i > 0 {
                    s.push_str("  ");
                }
                if numeric(c) {
                    s.push_str(&" ".repeat(pad));
                    s.push_str(c);
                } else {
                    s.push_str(c);
                    s.push_str(&" ".repeat(pad));
                }
            }
            out.push_str(s.trim_end());
            out.push('\n');
        };
        line(&mut out, &self.header);
        let rule: Vec<String> = width.iter().map(|w| "-".repeat(*w)).collect();
        line(&mut out, &rule);
        for r in &self.rows {
            line(&mut out, r);
        }
        out
    }
}

/// `1234567` as `1,234,567`.
pub fn thousands(n: u64) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (i, ch) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(ch);
    }
    out
}

/// Bytes in KiB/MiB with one decimal.
pub fn bytes(n: u64) -> String {
    if n < 1024 {
        format!("{n} B")
    } else if n < 1024 * 1024 {
        format!("{:.1} KiB", n as f64 / 1024.0)
    } else if n < 1024 * 1024 * 1024 {
        format!("{:.1} MiB", n as f64 / (1024.0 * 1024.0))
    } else {
        format!("{:.2} GiB", n as f64 / (1024.0 * 1024.0 * 1024.0))
    }
}

/// A duration in milliseconds with three significant digits.
pub fn ms(secs: f64) -> String {
    let m = secs * 1e3;
    if m >= 100.0 {
        format!("{m:.0}")
    } else if m >= 10.0 {
        format!("{m:.1}")
    } else {
        format!("{m:.2}")
    }
}

/// A UUID as 32 hex digits in 8-4-4-4-12 groups.
pub fn uuid(u: &[u8; 16]) -> String {
    let h: Vec<String> = u.iter().map(|b| format!("{b:02x}")).collect();
    format!(
        "{}-{}-{}-{}-{}",
        h[..4].concat(),
        h[4..6].concat(),
        h[6..8].concat(),
        h[8..10].concat(),
        h[10..].concat()
    )
}

/// Names of the set bits of `VkBuildAccelerationStructureFlagsKHR`.
pub fn build_flag_names(flags: u32) -> Vec<String> {
    use vk::BuildAccelerationStructureFlagsKHR as F;
    let known = [
        (F::ALLOW_UPDATE, "ALLOW_UPDATE"),
        (F::ALLOW_COMPACTION, "ALLOW_COMPACTION"),
        (F::PREFER_FAST_TRACE, "PREFER_FAST_TRACE"),
        (F::PREFER_FAST_BUILD, "PREFER_FAST_BUILD"),
        (F::LOW_MEMORY, "LOW_MEMORY"),
        (F::ALLOW_DATA_ACCESS, "ALLOW_DATA_ACCESS"),
    ];
    let mut out = Vec::new();
    let mut rest = flags;
    for (f, name) in known {
        if flags & f.as_raw() != 0 {
            out.push(name.to_string());
            rest &= !f.as_raw();
        }
    }
    if rest != 0 {
        out.push(format!("{rest:#x}"));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formatting() {
        assert_eq!(thousands(1234567), "1,234,567");
        assert_eq!(thousands(12), "12");
        assert_eq!(bytes(2048), "2.0 KiB");
        assert_eq!(uuid(&[0xab; 16]), "abababab-abab-abab-abab-abababababab");
        assert_eq!(
            build_flag_names(0x4 | 0x2),
            vec!["ALLOW_COMPACTION", "PREFER_FAST_TRACE"]
        );
    }

    #[test]
    fn table_alignment() {
        let mut t = Table::new(["name", "n"]);
        t.row(["a", "1"]);
        t.row(["long name", "1,000"]);
        let s = t.render();
        assert!(s.contains("a              1\n"), "{s}");
    }
}
