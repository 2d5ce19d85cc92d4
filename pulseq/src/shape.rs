//! Pulseq shapes: the run-length compression of the derivative that the
//! `[SHAPES]` section uses, and the text of one shape.
//!
//! A shape is stored as its first sample followed by the differences between
//! consecutive samples; a run of two or more equal differences `d` is written
//! `d d n` (the value twice, then the number of further repetitions `n`). A
//! reader recognises a stored shape as uncompressed when it holds exactly
//! `num_samples` values, so the compressed form is only used when it is
//! strictly shorter, and only when decompressing it gives the samples back.

/// Samples as stored in the file: compressed when that is shorter and exact,
/// the samples themselves otherwise.
pub(crate) fn stored_samples(samples: &[f64]) -> Vec<f64> {
    let packed = compress(samples);
    if packed.len() < samples.len() && decompress(&packed, samples.len()) == samples {
        packed
    } else {
        samples.to_vec()
    }
}

/// The derivative, run-length encoded.
fn compress(samples: &[f64]) -> Vec<f64> {
    let mut diffs = Vec::with_capacity(samples.len());
    let mut previous = 0.0;
    for &s in samples {
        diffs.push(s - previous);
        previous = s;
    }
    let mut out = Vec::new();
    let mut i = 0;
    while i < diffs.len() {
        let value = diffs[i];
        let mut run = 1;
        while i + run < diffs.len() && diffs[i + run].to_bits() == value.to_bits() {
            run += 1;
        }
        if run == 1 {
            out.push(value);
        } else {
            out.extend([value, value, (run - 2) as f64]);
        }
        i += run;
    }
    out
}

/// Inverse of [`compress`], as a reader does it (used to verify the encoding).
/// Returns an empty vector when `packed` is malformed.
fn decompress(packed: &[f64], num_samples: usize) -> Vec<f64> {
    let mut diffs = Vec::with_capacity(num_samples);
    let mut i = 0;
    while i < packed.len() {
        if i + 1 < packed.len() && packed[i + 1].to_bits() == packed[i].to_bits() {
            let Some(&count) = packed.get(i + 2) else {
                return Vec::new();
            };
            if !(count >= 0.0 && count.fract() == 0.0)
                || diffs.len() + count as usize + 2 > num_samples
            {
                return Vec::new();
            }
            diffs.resize(diffs.len() + count as usize + 2, packed[i]);
            i += 3;
        } else {
            diffs.push(packed[i]);
            i += 1;
        }
    }
    if diffs.len() != num_samples {
        return Vec::new();
    }
    let mut sum = 0.0;
    diffs
        .iter()
        .map(|d| {
            sum += d;
            sum
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_shape_compresses_to_three_values() {
        let ones = vec![1.0; 1000];
        assert_eq!(stored_samples(&ones), vec![1.0, 0.0, 0.0, 997.0]);
        let zeros = vec![0.0; 1000];
        assert_eq!(stored_samples(&zeros), vec![0.0, 0.0, 998.0]);
    }

    #[test]
    fn the_specification_example_round_trips() {
        let shape = [
            0.0, 0.1, 0.25, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.75, 0.5, 0.25, 0.0,
        ];
        let packed = compress(&shape);
        let back = decompress(&packed, shape.len());
        assert_eq!(back.len(), shape.len());
        for (a, b) in back.iter().zip(shape) {
            assert!((a - b).abs() < 1e-12);
        }
    }

    #[test]
    fn short_or_irregular_shapes_stay_uncompressed() {
        let points = [0.0, 10.0, 1990.0, 2000.0];
        assert_eq!(stored_samples(&points), points.to_vec());
        let two = [0.5, 1.0];
        assert_eq!(stored_samples(&two), two.to_vec());
    }

    #[test]
    fn malformed_packing_decompresses_to_nothing() {
        assert!(decompress(&[1.0, 1.0], 5).is_empty());
        assert!(decompress(&[1.0, 1.0, 10.0], 5).is_empty());
        assert!(decompress(&[1.0, 2.0], 3).is_empty());
    }
}
