//! Stopping a benchmark or an evaluation at its next safe point. The command line hands a run
//! the flag that Ctrl-C (SIGINT) and SIGTERM set ([`crate::bake::CancelFlag`], as a flight and
//! a soak take it); the run tests it between frames, settings and views and inside its warm-ups
//! ([`Stop::check`], [`Stop::warm_up`]). A step that finds it set returns [`Stopped`], which the
//! run catches ([`caught`]) to write what it measured, its report marked interrupted.

use crate::bake::CancelFlag;
use crate::camera::Camera;
use crate::renderer::WarmUp;
use crate::tools::Scene;

/// What a step of a run returns when its stop was asked for: not a failure, the run writes
/// what it measured (see [`caught`]).
#[derive(Debug, thiserror::Error)]
#[error("the run was stopped (Ctrl-C)")]
pub struct Stopped;

/// A run's stop: the flag that ends it early, or none (the run goes to its end).
#[derive(Clone, Debug, Default)]
pub struct Stop(Option<CancelFlag>);

impl Stop {
    /// A stop on `flag` (none: never asked).
    pub fn new(flag: Option<CancelFlag>) -> Self {
        Self(flag)
    }

    /// Whether the run was asked to stop.
    pub fn requested(&self) -> bool {
        self.0.as_ref().is_some_and(CancelFlag::is_cancelled)
    }

    /// A safe point: [`Stopped`] if the run was asked to stop.
    pub fn check(&self) -> Result<(), Stopped> {
        if self.requested() {
            Err(Stopped)
        } else {
            Ok(())
        }
    }

    /// Brings the tiles `camera` wants into `scene`, waiting up to `timeout`
    /// ([`Scene::warm_up_until`]), and [`Stopped`] if the run was asked to stop meanwhile (the
    /// warm-up ends within a few milliseconds of it): a frame drawn then would be measured
    /// without its tiles.
    pub fn warm_up(
        &self,
        scene: &mut Scene,
        camera: &Camera,
        timeout: std::time::Duration,
    ) -> anyhow::Result<WarmUp> {
        let report = scene.warm_up_until(camera, timeout, &|| self.requested())?;
        self.check()?;
        Ok(report)
    }
}

/// Whether `result`, a run's measurements, ended at a [`Stopped`] (however deep it was
/// raised): `Ok(true)` then, `Ok(false)` when they ran to their end; any other error is passed
/// on.
pub fn caught(result: anyhow::Result<()>) -> anyhow::Result<bool> {
    match result {
        Ok(()) => Ok(false),
        Err(e) if e.is::<Stopped>() => Ok(true),
        Err(e) => Err(e),
    }
}

/// A chart's title, with "(interrupted: partial)" after it when the run was stopped early.
pub fn chart_title(title: impl Into<String>, interrupted: bool) -> String {
    let title = title.into();
    if interrupted {
        format!("{title} (interrupted: partial)")
    } else {
        title
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anyhow::Context as _;

    #[test]
    fn a_stop_is_caught_through_context_and_other_errors_pass() {
        let flag = CancelFlag::new();
        let stop = Stop::new(Some(flag.clone()));
        assert!(!stop.requested() && stop.check().is_ok());
        assert!(!caught(Ok(())).unwrap());
        flag.cancel();
        assert!(stop.requested());
        let deep: anyhow::Result<()> = Err(stop.check().unwrap_err()).context("truth sub-sample 3");
        assert!(caught(deep).unwrap());
        let other: anyhow::Result<()> = Err(anyhow::anyhow!("disk full"));
        assert_eq!(caught(other).unwrap_err().to_string(), "disk full");
        // No flag: never stopped.
        assert!(Stop::default().check().is_ok());
        assert_eq!(chart_title("t", false), "t");
        assert_eq!(chart_title("t", true), "t (interrupted: partial)");
    }
}
