//! `hybrid view`: the interactive viewer (crate `hybrid-view`).

use hybrid_scene::{Budget, Policy};

use crate::CliError;
use crate::args::{BackendChoice, PolicyChoice, ViewArgs};

pub fn run(args: ViewArgs) -> Result<(), CliError> {
    args.heuristic.check()?;
    if !args.target_ms.is_finite() || args.target_ms <= 0.0 {
        return Err(CliError::bad_input(format!("--target-ms must be a number of milliseconds > 0, got {}", args.target_ms)));
    }
    let budget = match (args.heuristic.budget, args.heuristic.budget_ms) {
        (Some(b), _) => Some(Budget::Cost(b)),
        (None, Some(ms)) => Some(Budget::Millis(ms)),
        (None, None) => None,
    };
    let options = hybrid_view::ViewOptions {
        scene: args.scene,
        backend: match args.backend {
            BackendChoice::Auto => hybrid_view::BackendChoice::Auto,
            BackendChoice::Cpu => hybrid_view::BackendChoice::Cpu,
            BackendChoice::Gpu => hybrid_view::BackendChoice::Gpu,
        },
        size: args.size,
        mode: args.mode,
        budget,
        policy: args.heuristic.policy.map(|p| match p {
            PolicyChoice::Paper => Policy::Paper,
            PolicyChoice::Knapsack => Policy::Knapsack,
        }),
        target_ms: args.target_ms,
        script: args.script,
        clip_capsule: args.capsule.clip_capsule,
        sphere_effects: !args.capsule.no_sphere_effects,
        primary_visibility: args.capsule.capsule_visibility.primary_visibility(),
        rt: args.capsule.rt.choice(),
        fallback: args.capsule.fallback.fallback(),
    };
    hybrid_view::run(options).map_err(|e| CliError { code: e.code, message: e.message, detail: None })
}
