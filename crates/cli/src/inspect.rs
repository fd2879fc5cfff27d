//! `hybrid inspect SCENE [--json]`: load, validate, print the paper's Table 4 row.

use hybrid_scene::{SceneStats, load_scene_or_model};

use crate::CliError;
use crate::args::InspectArgs;

pub fn run(args: InspectArgs) -> Result<(), CliError> {
    let scene = load_scene_or_model(&args.scene)?;
    let stats = SceneStats::of(&scene);
    if args.json {
        let json = serde_json::to_string_pretty(&stats).map_err(|e| CliError::failure(e.to_string()))?;
        println!("{json}");
    } else {
        println!("{}", args.scene.display());
        println!("{stats}");
    }
    Ok(())
}
