//! Which frames a tip-following profile pools: the frames its steady
//! profile explains (dropping the others, one at a time), and, for the
//! frames of one insertion, a window of tip depth around each target
//! (`crate::follow` fits the profile).

use nalgebra::DVector;

use crate::error::ForceError;
use crate::estimate::{EstimatorOptions, ShaftDistribution, ShaftEstimator};
use crate::follow::{FollowOptions, FollowedFrame, FrameCheck, TipFollowing, check, fit_profile};
use crate::observe::{Frame, Insertion};
use crate::regularise::DISCREPANCY_SAFETY;
use crate::respond::MaterialField;

/// [`fit_tip_following`](crate::fit_tip_following) on `frames`, then,
/// while its profile leaves some of them unexplained, again without the
/// worst unexplained one (the largest [`FrameCheck::excess`]), one frame
/// at a time: a density that is steady over part of the pool only (the
/// first millimetres of an insertion, a change of velocity) is fitted to
/// the larger steady part, whose frames the compromise fits best; then the
/// dropped frames the final profile explains are taken back (one pass).
/// Nothing is dropped when the frames' own fits miss the stated noise
/// (model error: the check cannot tell steady frames from the rest).
/// Returns the profile and the indices (into `frames`) of the frames it
/// was fitted to. The profile reaches as far behind the tip as the
/// longest of `frames`, so that it can show the dropped frames too
/// (flagged).
///
/// Errors: those of [`fit_tip_following`](crate::fit_tip_following).
pub fn fit_explained_pool(
    frames: &[&FollowedFrame],
) -> Result<(TipFollowing, Vec<usize>), ForceError> {
    let nodes = frames.iter().map(|f| f.nodes()).max().unwrap_or(0);
    let own_misfit: f64 = frames.iter().map(|f| f.single_misfit).sum();
    let data: usize = frames.iter().map(|f| f.data.len()).sum();
    let own_fits_reach_noise = own_misfit <= DISCREPANCY_SAFETY * DISCREPANCY_SAFETY * data as f64;
    let mut kept: Vec<usize> = (0..frames.len()).collect();
    loop {
        let members: Vec<&FollowedFrame> = kept.iter().map(|&k| frames[k]).collect();
        let fit = fit_profile(&members, nodes)?;
        if !own_fits_reach_noise {
            // The frames' own fits miss the stated noise (model error):
            // the check cannot tell steady frames from the rest, and all
            // stay flagged.
            return Ok((fit, kept));
        }
        let worst = (0..kept.len())
            .filter(|&i| !fit.frames[i].is_explained())
            .max_by(|&i, &j| fit.frames[i].excess().total_cmp(&fit.frames[j].excess()));
        match worst {
            Some(i) if kept.len() > 1 => {
                kept.remove(i);
            }
            _ => return readmit(frames, fit, kept, nodes),
        }
    }
}

/// One pass of taking back the dropped frames that the final profile
/// explains (a steady frame can be dropped while the compromise still
/// leaned towards the unsteady ones); kept if the refit still explains
/// every frame it is fitted to.
fn readmit(
    frames: &[&FollowedFrame],
    fit: TipFollowing,
    kept: Vec<usize>,
    nodes: usize,
) -> Result<(TipFollowing, Vec<usize>), ForceError> {
    let profile = DVector::from_column_slice(&fit.density);
    let back: Vec<usize> = (0..frames.len())
        .filter(|k| !kept.contains(k) && check(frames[*k], &profile).is_explained())
        .collect();
    if back.is_empty() || !fit.frames.iter().all(FrameCheck::is_explained) {
        return Ok((fit, kept));
    }
    let mut wider: Vec<usize> = kept.iter().chain(&back).copied().collect();
    wider.sort_unstable();
    let members: Vec<&FollowedFrame> = wider.iter().map(|&k| frames[k]).collect();
    let refit = fit_profile(&members, nodes)?;
    Ok(if refit.frames.iter().all(FrameCheck::is_explained) {
        (refit, wider)
    } else {
        (fit, kept)
    })
}

/// The tip-following distributions at the frames `targets` of one
/// insertion: for each, the profile pooled over the frames that
/// [`FollowOptions::window_spacings`] selects (every frame of `insertion`
/// is a candidate; thin the insertion to pool fewer), fitted by
/// [`fit_explained_pool`], shown along the target's shaft
/// ([`TipFollowing::distribution`], flagged if the profile does not
/// explain the target). Each frame is prepared once, and one profile
/// serves every target with the same pool.
///
/// Errors: those of [`ShaftEstimator::new`], [`ShaftEstimator::follow`]
/// and [`fit_tip_following`](crate::fit_tip_following); a target index out of range.
pub fn tip_following_distributions(
    insertion: &Insertion,
    material: &MaterialField,
    options: EstimatorOptions,
    follow: FollowOptions,
    targets: &[usize],
) -> Result<Vec<ShaftDistribution>, ForceError> {
    if let Some(w) = follow.window_spacings {
        crate::error::positive("pool window", w)?;
    }
    let estimator = ShaftEstimator::new(insertion, material, options)?;
    let reach = |f: &Frame| f.tip[1] / f.axis()[1];
    let mut prepared: Vec<Option<FollowedFrame>> = vec![None; insertion.frames.len()];
    let mut fitted: Option<(Vec<usize>, TipFollowing)> = None;
    let mut out = Vec::with_capacity(targets.len());
    for &target in targets {
        let centre = insertion.frames.get(target).map(reach).ok_or_else(|| {
            ForceError::Mismatch(format!(
                "target frame {target} requested, the insertion has {}",
                insertion.frames.len()
            ))
        })?;
        let pool: Vec<usize> = (0..insertion.frames.len())
            .filter(|&j| {
                follow.window_spacings.is_none_or(|w| {
                    (reach(&insertion.frames[j]) - centre).abs() <= w * estimator.marker_spacing()
                })
            })
            .collect();
        for &j in &pool {
            if prepared[j].is_none() {
                prepared[j] =
                    Some(estimator.follow(insertion, &insertion.frames[j], follow.spacing)?);
            }
        }
        if fitted.as_ref().is_none_or(|(p, _)| *p != pool) {
            let members: Vec<&FollowedFrame> =
                pool.iter().filter_map(|&j| prepared[j].as_ref()).collect();
            fitted = Some((pool, fit_explained_pool(&members)?.0));
        }
        let (_, profile) = fitted.as_ref().expect("fitted above");
        let frame = prepared[target]
            .as_ref()
            .expect("the target lies in its own pool");
        out.push(profile.distribution(frame)?);
    }
    Ok(out)
}
