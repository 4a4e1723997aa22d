//! Write: rows of one beam into Arrow batches of the `shots/` schema (docs/schemas.md).

use std::sync::Arc;

use arrow::array::{ArrayRef, BooleanArray, Float32Builder, ListBuilder, PrimitiveArray, RecordBatch, StringArray};
use arrow::datatypes::{
    ArrowPrimitiveType, Float64Type, Int16Type, Int8Type, SchemaRef, UInt32Type, UInt64Type, UInt8Type,
};

use super::join::Row;
use crate::dataset::shots::{col, ALGORITHMS, VERTICAL_DATUM};
use crate::error::{Error, Result};
use crate::io::gedi::{L1bBeam, L2aBeam};
use crate::kernels::gedi::{BeamType, RH_LEN};

/// Everything needed to turn rows of one beam into a batch.
pub(super) struct BatchContext<'a> {
    pub(super) schema: &'a SchemaRef,
    pub(super) granule: &'a str,
    pub(super) beam: &'a str,
    pub(super) beam_type: BeamType,
    pub(super) l1b: Option<&'a L1bBeam>,
    pub(super) l2a: Option<&'a L2aBeam>,
    pub(super) geoid_offset: Option<f64>,
}

/// `v[i]` when both the optional column and the row index are present.
pub(super) fn at<T: Copy>(v: &Option<Vec<T>>, i: Option<usize>) -> Option<T> {
    Some(v.as_ref()?[i?])
}

/// Row `i` of a row-major N×101 RH array.
pub(super) fn rh_row(v: &[f32], i: usize) -> &[f32] {
    &v[i * RH_LEN..(i + 1) * RH_LEN]
}

pub(super) fn prim<T: ArrowPrimitiveType>(rows: &[Row], f: impl Fn(&Row) -> Option<T::Native>) -> ArrayRef {
    Arc::new(rows.iter().map(f).collect::<PrimitiveArray<T>>())
}

pub(super) fn f64s(rows: &[Row], f: impl Fn(&Row) -> Option<f64>) -> ArrayRef {
    prim::<Float64Type>(rows, f)
}

pub(super) fn lists<'r>(rows: &'r [Row], f: impl Fn(&'r Row) -> Option<&'r [f32]>) -> ArrayRef {
    let mut b = ListBuilder::new(Float32Builder::new());
    for r in rows {
        match f(r) {
            Some(v) => {
                b.values().append_slice(v);
                b.append(true);
            }
            None => b.append(false),
        }
    }
    Arc::new(b.finish())
}

pub(super) fn strings<'r>(rows: &'r [Row], f: impl Fn(&'r Row) -> Option<&'r str>) -> ArrayRef {
    Arc::new(rows.iter().map(f).collect::<StringArray>())
}

impl BatchContext<'_> {
    pub(super) fn batch(&self, rows: &[Row]) -> Result<RecordBatch> {
        let (l1, l2) = (self.l1b, self.l2a);
        // Accessors returning None when the row lacks that side.
        let a1 = |r: &Row| l1.zip(r.l1b);
        let a2 = |r: &Row| l2.zip(r.l2a);

        let mut cols: Vec<(String, ArrayRef)> = vec![
            (col::GRANULE.into(), strings(rows, |_| Some(self.granule))),
            (col::SHOT_NUMBER.into(), prim::<UInt64Type>(rows, |r| Some(r.shot_number))),
            (col::BEAM.into(), strings(rows, |_| Some(self.beam))),
            (col::BEAM_TYPE.into(), strings(rows, |_| Some(self.beam_type.as_str()))),
            (col::IN_L1B.into(), Arc::new(rows.iter().map(|r| Some(r.l1b.is_some())).collect::<BooleanArray>())),
            (col::IN_L2A.into(), Arc::new(rows.iter().map(|r| Some(r.l2a.is_some())).collect::<BooleanArray>())),
            (
                col::DELTA_TIME.into(),
                f64s(rows, |r| {
                    a1(r)
                        .and_then(|(b, i)| at(&b.delta_time, Some(i)))
                        .or_else(|| a2(r).and_then(|(b, i)| at(&b.delta_time, Some(i))))
                }),
            ),
            (col::LAT_BIN0.into(), f64s(rows, |r| a1(r).map(|(b, i)| b.lat_bin0[i]))),
            (col::LON_BIN0.into(), f64s(rows, |r| a1(r).map(|(b, i)| b.lon_bin0[i]))),
            (col::LAT_LASTBIN.into(), f64s(rows, |r| a1(r).map(|(b, i)| b.lat_lastbin[i]))),
            (col::LON_LASTBIN.into(), f64s(rows, |r| a1(r).map(|(b, i)| b.lon_lastbin[i]))),
            (col::LAT_LOWESTMODE.into(), f64s(rows, |r| a2(r).and_then(|(b, i)| b.lowestmode(i)).map(|p| p.0))),
            (col::LON_LOWESTMODE.into(), f64s(rows, |r| a2(r).and_then(|(b, i)| b.lowestmode(i)).map(|p| p.1))),
            (col::X.into(), f64s(rows, |r| r.xy.map(|p| p.0))),
            (col::Y.into(), f64s(rows, |r| r.xy.map(|p| p.1))),
            (col::XY_SOURCE.into(), strings(rows, |r| r.xy.map(|p| p.2.as_str()))),
            (col::ELEVATION_BIN0.into(), f64s(rows, |r| a1(r).map(|(b, i)| b.elevation_bin0[i]))),
            (col::ELEVATION_LASTBIN.into(), f64s(rows, |r| a1(r).map(|(b, i)| b.elevation_lastbin[i]))),
            (col::RX_WAVEFORM.into(), lists(rows, |r| a1(r).and_then(|(b, i)| b.rx.get(i)))),
            (col::RX_SAMPLE_COUNT.into(), prim::<UInt32Type>(rows, |r| a1(r).map(|(b, i)| b.rx.spans[i].1 as u32))),
            (col::TX_WAVEFORM.into(), lists(rows, |r| a1(r).and_then(|(b, i)| b.tx.as_ref()?.get(i)))),
            (col::NOISE_MEAN_CORRECTED.into(), f64s(rows, |r| a1(r).and_then(|(b, i)| at(&b.noise_mean, Some(i))))),
            (col::NOISE_STDDEV_CORRECTED.into(), f64s(rows, |r| a1(r).and_then(|(b, i)| at(&b.noise_stddev, Some(i))))),
            (
                col::STALE_RETURN_FLAG.into(),
                prim::<UInt8Type>(rows, |r| a1(r).and_then(|(b, i)| at(&b.stale_return_flag, Some(i)))),
            ),
            (col::DEGRADE.into(), prim::<Int8Type>(rows, |r| a1(r).and_then(|(b, i)| at(&b.degrade, Some(i))))),
            (col::GEOID.into(), f64s(rows, |r| a1(r).and_then(|(b, i)| at(&b.geoid, Some(i))))),
            (
                col::GEOID_OFFSET_USED.into(),
                f64s(rows, |r| self.geoid_offset.or_else(|| a1(r).and_then(|(b, i)| at(&b.geoid, Some(i))))),
            ),
            (col::VERTICAL_DATUM.into(), strings(rows, |_| Some(VERTICAL_DATUM))),
            (col::QUALITY_FLAG.into(), prim::<UInt8Type>(rows, |r| a2(r).map(|(b, i)| b.quality_flag[i]))),
            (col::DEGRADE_FLAG.into(), prim::<UInt8Type>(rows, |r| a2(r).map(|(b, i)| b.degrade_flag[i]))),
            (col::SENSITIVITY.into(), f64s(rows, |r| a2(r).map(|(b, i)| b.sensitivity[i]))),
            (col::SELECTED_ALGORITHM.into(), prim::<UInt8Type>(rows, |r| a2(r).map(|(b, i)| b.selected_algorithm[i]))),
            (col::ELEV_LOWESTMODE.into(), f64s(rows, |r| a2(r).map(|(b, i)| b.elev_lowestmode[i]))),
            (col::RH.into(), lists(rows, |r| a2(r).map(|(b, i)| rh_row(&b.rh, i)))),
            (col::ENERGY_TOTAL.into(), f64s(rows, |r| a2(r).and_then(|(b, i)| at(&b.energy_total, Some(i))))),
        ];
        for (a, (names, window)) in ALGORITHMS.iter().enumerate() {
            let alg = |r: &Row| a2(r).map(|(b, i)| (&b.algorithms[a], i));
            cols.extend([
                (
                    names.elev_lowestmode.into(),
                    f64s(rows, |r| alg(r).and_then(|(g, i)| at(&g.elev_lowestmode, Some(i)))),
                ),
                (names.rh.into(), lists(rows, |r| alg(r).and_then(|(g, i)| Some(rh_row(g.rh.as_ref()?, i))))),
                (names.sensitivity.into(), f64s(rows, |r| alg(r).and_then(|(g, i)| at(&g.sensitivity, Some(i))))),
                (
                    names.quality_flag.into(),
                    prim::<UInt8Type>(rows, |r| alg(r).and_then(|(g, i)| at(&g.quality_flag, Some(i)))),
                ),
                (window.toploc.into(), f64s(rows, |r| alg(r).and_then(|(g, i)| at(&g.toploc, Some(i))))),
                (window.botloc.into(), f64s(rows, |r| alg(r).and_then(|(g, i)| at(&g.botloc, Some(i))))),
                (window.zcross.into(), f64s(rows, |r| alg(r).and_then(|(g, i)| at(&g.zcross, Some(i))))),
            ]);
        }
        let u8_lc = |f: fn(&L2aBeam) -> &Option<Vec<u8>>| {
            prim::<UInt8Type>(rows, move |r| a2(r).and_then(|(b, i)| at(f(b), Some(i))))
        };
        let i16_lc = |f: fn(&L2aBeam) -> &Option<Vec<i16>>| {
            prim::<Int16Type>(rows, move |r| a2(r).and_then(|(b, i)| at(f(b), Some(i))))
        };
        cols.extend([
            (col::LEAF_OFF_FLAG.into(), u8_lc(|b| &b.leaf_off_flag)),
            (col::LEAF_OFF_DOY.into(), i16_lc(|b| &b.leaf_off_doy)),
            (col::LEAF_ON_DOY.into(), i16_lc(|b| &b.leaf_on_doy)),
            (col::PFT_CLASS.into(), u8_lc(|b| &b.pft_class)),
            (col::REGION_CLASS.into(), u8_lc(|b| &b.region_class)),
            (col::URBAN_PROPORTION.into(), u8_lc(|b| &b.urban_proportion)),
            (col::LANDSAT_WATER_PERSISTENCE.into(), u8_lc(|b| &b.landsat_water_persistence)),
        ]);

        // Order the columns by the schema, so the schema stays the single definition of order.
        let mut by_name: std::collections::HashMap<String, ArrayRef> = cols.into_iter().collect();
        let arrays = self
            .schema
            .fields()
            .iter()
            .map(|f| by_name.remove(f.name()).ok_or_else(|| Error::Usage(format!("internal: no column {}", f.name()))))
            .collect::<Result<Vec<_>>>()?;
        RecordBatch::try_new(self.schema.clone(), arrays).map_err(|e| Error::table(self.granule, e))
    }
}
