//! The camera side of a bundle, as the commands use it: the work is
//! `needle-vision`'s (`needle_vision::calibrate_from_bundle`,
//! `track_untracked_trials`); this prints what it did.

use needle_data::LoadedBundle;
use needle_vision::track_untracked_trials;

/// Gives the bundle's trials that have frames but no `markers.csv` the
/// tracks of their frames (in memory), prints what was done and returns
/// the same lines (none when no trial needed it).
pub fn track_untracked(bundle: &mut LoadedBundle) -> Result<Vec<String>, String> {
    let done = track_untracked_trials(bundle).map_err(|e| e.to_string())?;
    let lines = done.summary();
    for line in &lines {
        println!("{line}");
    }
    Ok(lines)
}
