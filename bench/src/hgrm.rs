//! HdrHistogram's percentile-distribution text (`.hgrm`), as its Java
//! `outputPercentileDistribution` writes it, so that HdrHistogram's own plotter
//! (HistogramLogAnalyzer, or the plotFiles.html page) reads our histograms unchanged.

use std::fmt::Write as _;

use hdrhistogram::Histogram;

/// The percentile distribution of `h`, values divided by `unit_scale` (1000: ns -> us), five
/// ticks per half distance to 100 %, as HdrHistogram's default.
pub fn percentile_distribution(h: &Histogram<u64>, unit_scale: f64) -> String {
    let mut out = String::new();
    let _ = write!(
        out,
        "{:>12} {:>14} {:>10} {:>14}\n\n",
        "Value", "Percentile", "TotalCount", "1/(1-Percentile)"
    );
    let mut total = 0u64;
    if !h.is_empty() {
        for v in h.iter_quantiles(5) {
            total += v.count_since_last_iteration();
            let value = v.value_iterated_to() as f64 / unit_scale;
            let q = v.quantile_iterated_to();
            if q < 1.0 {
                let _ = writeln!(
                    out,
                    "{value:>12.3} {q:>2.12} {total:>10} {:>14.2}",
                    1.0 / (1.0 - q)
                );
            } else {
                let _ = writeln!(out, "{value:>12.3} {q:>2.12} {total:>10}");
            }
        }
    }
    let (mean, stdev) = if h.is_empty() {
        (0.0, 0.0)
    } else {
        (h.mean() / unit_scale, h.stdev() / unit_scale)
    };
    let _ = writeln!(
        out,
        "#[Mean    = {mean:>12.3}, StdDeviation   = {stdev:>12.3}]"
    );
    let _ = writeln!(
        out,
        "#[Max     = {:>12.3}, Total count    = {:>12}]",
        h.max() as f64 / unit_scale,
        h.len()
    );
    // HdrHistogram's sub-bucket count: the power of two that holds 2 x 10^digits.
    let sub_buckets = 1u64 << (2.0 * 10f64.powi(i32::from(h.sigfig()))).log2().ceil() as u32;
    let _ = writeln!(
        out,
        "#[Buckets = {:>12}, SubBuckets     = {:>12}]",
        h.buckets(),
        sub_buckets
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rows parse back as HdrHistogram's plotter reads them: value, percentile (as a
    /// fraction), cumulative count, 1/(1-percentile); percentiles rise to 1 and counts to the
    /// total; the footer holds mean, max and count.
    #[test]
    fn the_distribution_parses_back_as_hdrhistogram_writes_it() {
        let mut h = common::latency::new_histogram();
        for i in 1..=1000u64 {
            h.record(i * 1000).unwrap(); // 1 .. 1000 us
        }
        let text = percentile_distribution(&h, 1000.0);
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split_whitespace().collect();
        assert_eq!(
            header,
            ["Value", "Percentile", "TotalCount", "1/(1-Percentile)"]
        );
        assert_eq!(lines.next(), Some(""));
        let mut rows = Vec::new();
        let mut footer = Vec::new();
        for l in lines {
            if l.starts_with("#[") {
                footer.push(l);
                continue;
            }
            let f: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            assert!(f.len() == 4 || f.len() == 3, "{l}");
            rows.push(f);
        }
        assert!(rows.len() > 20);
        for w in rows.windows(2) {
            assert!(w[1][0] >= w[0][0] && w[1][1] >= w[0][1] && w[1][2] >= w[0][2]);
        }
        let last = rows.last().unwrap();
        assert_eq!((last[1], last[2]), (1.0, 1000.0));
        // Values as the histogram holds them: within its precision (1 % at 2 digits).
        assert!((last[0] - 1000.0).abs() < 10.0, "{}", last[0]);
        let median = rows.iter().find(|r| r[1] >= 0.5).unwrap();
        assert!((median[0] - 500.0).abs() < 5.0, "{median:?}");
        assert_eq!(footer.len(), 3);
        assert!(
            footer[0].contains("Mean") && footer[0].contains(" 500."),
            "{}",
            footer[0]
        );
        assert!(
            footer[1].contains("Total count") && footer[1].ends_with("1000]"),
            "{}",
            footer[1]
        );
        let sub = 1u64 << (2.0 * 10f64.powi(i32::from(h.sigfig()))).log2().ceil() as u32;
        assert!(
            footer[2].contains("SubBuckets") && footer[2].ends_with(&format!("{sub}]")),
            "{}",
            footer[2]
        );
    }
}
