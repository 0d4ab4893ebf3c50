//! The sway spring's integrators against their stability theory, through the eval itself
//! (`verdant eval sway`), and the renderer's integrator over ten minutes with frame hitches.

use verdant::tools::eval_sway::{self as sway, EVAL_STEPS_S, HITCH_S, bounded_for};
use verdant::tools::sway_integrators::{EulerLimits, Integrator, Preset, RENDERER_INTEGRATOR};
use verdant::wind::spring::SwaySpring;

/// `|1 + dt lambda| < 1` for both eigenvalues `lambda = -c/2 +- sqrt(c^2/4 - k)` of the
/// spring's matrix `[[0, 1], [-k, -c]]`: when explicit Euler, which multiplies each mode by
/// `1 + dt lambda`, is stable. Computed from the eigenvalues, not from the closed form.
fn explicit_euler_stable_in_theory(spring: &SwaySpring, dt: f64) -> bool {
    let (k, c) = (f64::from(spring.stiffness), f64::from(spring.damping));
    let disc = c * c / 4.0 - k;
    if disc < 0.0 {
        // Complex pair -c/2 +- i w_d: |1 + dt lambda|^2 = (1 - dt c/2)^2 + dt^2 w_d^2.
        let (re, im) = (1.0 - dt * c / 2.0, dt * (-disc).sqrt());
        re * re + im * im < 1.0
    } else {
        [-c / 2.0 + disc.sqrt(), -c / 2.0 - disc.sqrt()]
            .iter()
            .all(|l| (1.0 + dt * l).abs() < 1.0)
    }
}

/// Jury's conditions for semi-implicit Euler's step matrix (trace `2 - c dt - k dt^2`,
/// determinant `1 - c dt`): `|det| < 1` and `|trace| < 1 + det`.
fn semi_implicit_euler_stable_in_theory(spring: &SwaySpring, dt: f64) -> bool {
    let (k, c) = (f64::from(spring.stiffness), f64::from(spring.damping));
    let (tr, det) = (2.0 - c * dt - k * dt * dt, 1.0 - c * dt);
    det.abs() < 1.0 && tr.abs() < 1.0 + det
}

#[test]
fn the_renderer_integrator_stays_bounded_for_ten_minutes_with_hitches() {
    for preset in Preset::ALL {
        let spring = preset.spring();
        for dt in EVAL_STEPS_S {
            // A 0.5 s hitch about every 5 s of frames.
            let every = ((5.0 / dt).round() as usize).max(1);
            for hitch in [None, Some((every, HITCH_S as f32))] {
                assert!(
                    bounded_for(RENDERER_INTEGRATOR, &spring, dt as f32, 600.0, hitch),
                    "{} at dt {dt}, hitches {hitch:?}",
                    preset.name()
                );
            }
        }
    }
}

#[test]
fn the_renderer_integrator_is_the_one_the_eval_finds_stable_everywhere() {
    let results = sway::evaluate_all();
    assert_eq!(
        results.len(),
        Preset::ALL.len() * Integrator::ALL.len() * EVAL_STEPS_S.len()
    );
    assert_eq!(sway::stable_everywhere(&results), vec![RENDERER_INTEGRATOR]);
    // An eval stopped early: an integrator run at some steps, or with one preset, is not
    // called stable everywhere, however its runs went.
    let stiff_only: Vec<_> = results
        .iter()
        .filter(|r| r.preset == Preset::ALL[0].name())
        .cloned()
        .collect();
    assert!(sway::stable_everywhere(&stiff_only).is_empty());
    let without_last_step: Vec<_> = results
        .iter()
        .filter(|r| r.dt_s != EVAL_STEPS_S[EVAL_STEPS_S.len() - 1])
        .cloned()
        .collect();
    assert!(sway::stable_everywhere(&without_last_step).is_empty());
    for r in results
        .iter()
        .filter(|r| r.integrator == RENDERER_INTEGRATOR)
    {
        assert!(r.stable && r.blew_up_at_s.is_none(), "{r:?}");
        // Bounded here means close to the wind: never more than twice its amplitude.
        assert!(r.max_abs_x < 2.0 * r.forcing_amplitude, "{r:?}");
    }
}

#[test]
fn explicit_euler_blows_up_where_theory_says() {
    for preset in Preset::ALL {
        let spring = preset.spring();
        for dt in EVAL_STEPS_S {
            let r = sway::evaluate(preset, Integrator::ExplicitEuler, dt);
            let theory = explicit_euler_stable_in_theory(&spring, dt);
            assert_eq!(
                r.stable,
                theory,
                "{} explicit Euler at dt {dt}: the eval says stable = {} (blew up at {:?}), \
                 theory says {theory} (limit c/k = {} s)",
                preset.name(),
                r.stable,
                r.blew_up_at_s,
                spring.explicit_euler_max_dt()
            );
            assert_eq!(theory, dt < spring.explicit_euler_max_dt());
            assert_eq!(
                theory,
                Integrator::ExplicitEuler.spectral_radius(&spring, dt) < 1.0
            );
        }
    }
    // On the stiff spring it fails from the first frame time above c/k on, and at every
    // larger one.
    let stiff = Preset::Stiff.spring();
    let verdicts: Vec<(f64, bool)> = EVAL_STEPS_S
        .iter()
        .map(|&dt| {
            (
                dt,
                sway::evaluate(Preset::Stiff, Integrator::ExplicitEuler, dt).stable,
            )
        })
        .collect();
    let first_failure = verdicts
        .iter()
        .find(|(_, stable)| !stable)
        .map(|&(dt, _)| dt)
        .expect("explicit Euler blows up somewhere on the stiff spring");
    let first_above_limit = EVAL_STEPS_S
        .iter()
        .copied()
        .find(|&dt| dt > stiff.explicit_euler_max_dt())
        .unwrap();
    assert_eq!(first_failure, first_above_limit);
    assert!(
        verdicts
            .iter()
            .all(|&(dt, stable)| stable == (dt < first_failure))
    );
    assert!(
        !verdicts.last().unwrap().1,
        "it must fail at the 0.5 s hitch"
    );
}

#[test]
fn semi_implicit_euler_blows_up_where_theory_says() {
    for preset in Preset::ALL {
        let spring = preset.spring();
        let limit = spring.semi_implicit_euler_max_dt();
        // Close to 2 / w: damping lowers the limit a little.
        assert!(limit < 2.0 / spring.omega() && limit > 1.5 / spring.omega());
        for dt in EVAL_STEPS_S {
            let r = sway::evaluate(preset, Integrator::SemiImplicitEuler, dt);
            let theory = semi_implicit_euler_stable_in_theory(&spring, dt);
            assert_eq!(
                r.stable,
                theory,
                "{} semi-implicit Euler at dt {dt}: the eval says stable = {} (blew up at \
                 {:?}), theory says {theory} (limit {limit} s)",
                preset.name(),
                r.stable,
                r.blew_up_at_s
            );
            assert_eq!(theory, dt < limit);
            assert_eq!(
                theory,
                Integrator::SemiImplicitEuler.spectral_radius(&spring, dt) < 1.0
            );
        }
    }
}

#[test]
fn neither_euler_step_survives_steady_half_second_frames() {
    for preset in Preset::ALL {
        let spring = preset.spring();
        for integrator in [Integrator::ExplicitEuler, Integrator::SemiImplicitEuler] {
            assert!(
                !bounded_for(integrator, &spring, HITCH_S as f32, 600.0, None),
                "{} {}",
                preset.name(),
                integrator.name()
            );
        }
    }
}

/// A stop asked for during the eval (Ctrl-C on the command line) ends it after the run under
/// way: the runs made are written to `sway.csv` and the charts, the report marked interrupted,
/// and an integrator that never ran is not called stable; asked for before the first run,
/// nothing is written.
#[test]
fn a_stopped_sway_eval_writes_the_runs_it_made() {
    use verdant::bake::CancelFlag;
    use verdant::tools::stop::Stop;
    let tmp = tempfile::tempdir().unwrap();
    let flag = CancelFlag::new();
    let stop = Stop::new(Some(flag.clone()));
    let out = tmp.path().join("sway");
    let mut heard = Vec::new();
    let report = sway::run_sway_eval(&out, &stop, &mut |done, total| {
        heard.push((done, total));
        if done == 2 {
            flag.cancel();
        }
    })
    .unwrap();
    assert_eq!(heard, [(1, 54), (2, 54)]);
    assert!(report.interrupted);
    assert_eq!(report.results.len(), 2);
    let csv = std::fs::read_to_string(out.join("sway.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    let first = Integrator::ALL[0].name();
    assert_eq!(rows.len(), 2, "{csv}");
    for (row, dt) in rows.iter().zip(EVAL_STEPS_S) {
        assert_eq!((row[0], row[1]), ("stiff", first), "{csv}");
        assert!((row[2].parse::<f64>().unwrap() - dt).abs() < 1e-6, "{csv}");
    }
    for chart in [
        "sway_error.png",
        "sway_error_soft.png",
        "sway_stability.png",
    ] {
        image::open(out.join(chart)).unwrap();
    }
    assert!(report.stable.iter().all(|i| i.name() == first));
    // Stopped before the first run: nothing measured, nothing written, no folder made.
    let none = tmp.path().join("none");
    let report = sway::run_sway_eval(&none, &stop, &mut |_, _| {}).unwrap();
    assert!(report.interrupted && report.results.is_empty());
    assert!(!none.exists());
}
