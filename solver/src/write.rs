//! Writing a table file (the generator's side; needs a heap): sections are
//! added by kind and laid out as `format` describes, with the SHA-256
//! trailer last.

extern crate alloc;

use crate::format::{
    Axis, ExplicitLayout, Section, CHECKSUM_BYTES, DIRECTORY_ENTRY_BYTES, FORMAT_VERSION,
    HEADER_BYTES, MAGIC, SECTION_ALIGN,
};
use crate::tables::Dims;
use alloc::vec;
use alloc::vec::Vec;
use sha2::{Digest, Sha256};

/// Collects the sections of one table file.
#[derive(Debug, Clone)]
pub struct TableWriter {
    dims: Dims,
    config_hash: [u8; 32],
    sections: Vec<Vec<u8>>,
}

impl TableWriter {
    /// An empty file for `dims` made from the config with SHA-256 `config_hash`.
    pub fn new(dims: Dims, config_hash: [u8; 32]) -> TableWriter {
        TableWriter {
            dims,
            config_hash,
            sections: vec![Vec::new(); Section::COUNT],
        }
    }

    fn section(&mut self, s: Section) -> &mut Vec<u8> {
        &mut self.sections[s.position()]
    }

    pub fn f64s(&mut self, s: Section, values: impl IntoIterator<Item = f64>) {
        let out = self.section(s);
        for v in values {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    pub fn u64s(&mut self, s: Section, values: impl IntoIterator<Item = u64>) {
        let out = self.section(s);
        for v in values {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    pub fn u32s(&mut self, s: Section, values: impl IntoIterator<Item = u32>) {
        let out = self.section(s);
        for v in values {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    pub fn u16s(&mut self, s: Section, values: impl IntoIterator<Item = u16>) {
        let out = self.section(s);
        for v in values {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    pub fn u8s(&mut self, s: Section, values: impl IntoIterator<Item = u8>) {
        self.section(s).extend(values);
    }

    /// The five axes, in `format::AXIS_*` order.
    pub fn axes(&mut self, axes: [Axis; 5]) {
        let out = self.section(Section::Axes);
        for a in axes {
            out.extend_from_slice(&a.start.to_le_bytes());
            out.extend_from_slice(&a.step.to_le_bytes());
            out.extend_from_slice(&(a.count as u64).to_le_bytes());
        }
    }

    /// One plan's metadata (`format::PLAN_META_BYTES`).
    pub fn plan_meta(&mut self, s: Section, cost: f64, iterations: u32, arrival_samples: u32) {
        let out = self.section(s);
        out.extend_from_slice(&cost.to_le_bytes());
        out.extend_from_slice(&iterations.to_le_bytes());
        out.extend_from_slice(&arrival_samples.to_le_bytes());
    }

    /// One explicit sample record (see `ExplicitLayout`).
    #[allow(clippy::too_many_arguments)]
    pub fn explicit_sample(
        &mut self,
        hessian: &[f64],
        gradient: &[f64],
        sensitivity: &[f64],
        cost: f64,
        cost_gradient: &[f64],
        cost_hessian: &[f64],
        source: u8,
        plan: u16,
        offset: u16,
        active: &[i8],
    ) {
        let layout = ExplicitLayout {
            n: self.dims.n,
            nx: self.dims.nx,
        };
        assert_eq!(
            hessian.len(),
            layout.hessian_len(),
            "explicit hessian length"
        );
        assert_eq!(gradient.len(), layout.n, "explicit gradient length");
        assert_eq!(
            sensitivity.len(),
            layout.n * layout.nx,
            "explicit sensitivity length"
        );
        assert_eq!(
            cost_gradient.len(),
            layout.nx,
            "explicit cost gradient length"
        );
        assert_eq!(
            cost_hessian.len(),
            layout.nx * layout.nx,
            "explicit cost hessian length"
        );
        assert_eq!(active.len(), layout.n, "explicit active set length");
        let out = &mut self.sections[Section::ExplicitSamples.position()];
        let start = out.len();
        for v in hessian.iter().chain(gradient).chain(sensitivity) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&cost.to_le_bytes());
        for v in cost_gradient.iter().chain(cost_hessian) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.push(source);
        out.extend_from_slice(&plan.to_le_bytes());
        out.extend_from_slice(&offset.to_le_bytes());
        out.extend(active.iter().map(|&a| a as u8));
        out.resize(start + layout.record_bytes(), 0);
    }

    /// The whole file: header, directory, sections (8-byte aligned), SHA-256.
    pub fn finish(self) -> Vec<u8> {
        let layout = ExplicitLayout {
            n: self.dims.n,
            nx: self.dims.nx,
        };
        let mut out = Vec::new();
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        out.extend_from_slice(&(Section::COUNT as u32).to_le_bytes());
        out.extend_from_slice(&self.config_hash);
        for d in [self.dims.m, self.dims.nx, self.dims.n, self.dims.k] {
            out.extend_from_slice(&(d as u32).to_le_bytes());
        }
        debug_assert_eq!(out.len(), HEADER_BYTES);
        let mut offset =
            (HEADER_BYTES + Section::COUNT * DIRECTORY_ENTRY_BYTES).next_multiple_of(SECTION_ALIGN);
        for (p, s) in Section::ALL.iter().enumerate() {
            let element = match s {
                Section::ExplicitSamples => layout.record_bytes(),
                s => s.element_bytes(),
            };
            let len = self.sections[p].len();
            out.extend_from_slice(&(*s as u32).to_le_bytes());
            out.extend_from_slice(&(element as u32).to_le_bytes());
            out.extend_from_slice(&(offset as u64).to_le_bytes());
            out.extend_from_slice(&(len as u64).to_le_bytes());
            offset = (offset + len).next_multiple_of(SECTION_ALIGN);
        }
        for bytes in &self.sections {
            out.resize(out.len().next_multiple_of(SECTION_ALIGN), 0);
            out.extend_from_slice(bytes);
        }
        let digest: [u8; CHECKSUM_BYTES] = Sha256::digest(&out).into();
        out.extend_from_slice(&digest);
        out
    }
}
