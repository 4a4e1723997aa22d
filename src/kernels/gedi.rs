//! GEDI product conventions shared by the reader (`ops::ingest_gedi`) and the granule writer
//! (`io::granule`): beam names and types, dataset names, the V2 product identifiers.
//!
//! Facts and their sources are in `docs/gedi-products.md` (shared docs) §1–§3.

/// The eight GEDI beam group names, coverage beams first.
pub const BEAM_NAMES: [&str; 8] =
    ["BEAM0000", "BEAM0001", "BEAM0010", "BEAM0011", "BEAM0101", "BEAM0110", "BEAM1000", "BEAM1011"];

/// Number of relative-height values per shot (RH0..RH100 at 1 % steps).
pub const RH_LEN: usize = 101;

/// Number of L2A algorithm settings (a1..a6).
pub const N_ALGORITHMS: usize = 6;

/// The kind of laser beam a group holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BeamType {
    /// Coverage beam (split laser, lower energy): BEAM0000..BEAM0011.
    Coverage,
    /// Full-power beam: BEAM0101, BEAM0110, BEAM1000, BEAM1011.
    FullPower,
}

impl BeamType {
    /// Classify a beam by its group name; `None` for a name that is not one of the eight beams.
    ///
    /// The name, not the per-shot `channel`, carries the beam type (gedi-products.md §1).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "BEAM0000" | "BEAM0001" | "BEAM0010" | "BEAM0011" => Some(BeamType::Coverage),
            "BEAM0101" | "BEAM0110" | "BEAM1000" | "BEAM1011" => Some(BeamType::FullPower),
            _ => None,
        }
    }

    /// The value of the `beam_type` column: `coverage` or `full_power`.
    pub fn as_str(self) -> &'static str {
        match self {
            BeamType::Coverage => "coverage",
            BeamType::FullPower => "full_power",
        }
    }

    /// The beam group's `description` attribute in GEDI files.
    pub fn description(self) -> &'static str {
        match self {
            BeamType::Coverage => "Coverage beam",
            BeamType::FullPower => "Full power beam",
        }
    }
}

/// Whether a group name looks like a GEDI beam group (`BEAM` + four binary digits).
pub fn is_beam_group(name: &str) -> bool {
    name.len() == 8 && name.starts_with("BEAM") && name[4..].bytes().all(|b| b == b'0' || b == b'1')
}

/// The per-shot `beam` number of a beam group: the decimal value of its binary suffix.
pub fn beam_number(name: &str) -> Option<u16> {
    is_beam_group(name).then(|| u16::from_str_radix(&name[4..], 2).ok()).flatten()
}
