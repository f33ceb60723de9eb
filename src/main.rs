//! `embodied`: plan, run and verify multi-robot systems of embodied agents.
#![forbid(unsafe_code)]

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use embodied::AppError;
use embodied::model_report::{load_robot, model_report, parse_q, render_text};

fn builtin_help() -> String {
    let mut s = String::from("Built-in robots (and where their numbers come from):\n");
    for (name, source) in embodied_models::builtin_summaries() {
        s.push_str(&format!("\n  {name}\n      {source}\n"));
    }
    s
}

#[derive(Parser, Debug)]
#[command(name = "embodied", version, about = "Deliberative planning and verification of multi-robot systems (embodied agents)")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Print a robot: joints, link poses, end effectors, self-collision and minimum distance at q.
    #[command(after_long_help = builtin_help())]
    Model {
        /// A built-in robot name (see --help) or a path to a URDF file.
        robot: String,
        /// SRDF for a URDF robot (disabled collision pairs, groups).
        #[arg(long)]
        srdf: Option<PathBuf>,
        /// Joint values, comma separated, in the robot's joint order (default: the home pose).
        #[arg(long, allow_hyphen_values = true)]
        q: Option<String>,
        /// Print one JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// List the built-in scenarios (name and one-line description).
    Scenarios {
        /// Print a JSON array of {"name", "description", "agents", "obstacles"}.
        #[arg(long)]
        json: bool,
    },
}

fn run(cli: Cli) -> Result<(), AppError> {
    match cli.command {
        Command::Model { robot, srdf, q, json } => {
            let robot = load_robot(&robot, srdf.as_deref())?;
            let q = match q {
                Some(text) => parse_q(&robot, &text)?,
                None => robot.home().to_vec(),
            };
            let report = model_report(&robot, &q);
            if json {
                let text = serde_json::to_string(&report).map_err(|e| AppError::Failed(e.to_string()))?;
                println!("{text}");
            } else {
                print!("{}", render_text(&report));
            }
            Ok(())
        }
        Command::Scenarios { json } => {
            let mut list = Vec::new();
            for (name, _) in embodied::scenario::BUILTIN_SCENARIOS {
                let sc = embodied::scenario::load_scenario(name)?;
                list.push(serde_json::json!({
                    "name": name,
                    "description": sc.description,
                    "agents": sc.agents.iter().map(|a| a.name.clone()).collect::<Vec<_>>(),
                    "obstacles": sc.obstacles.len(),
                    "default": *name == embodied::scenario::DEFAULT_SCENARIO,
                }));
            }
            if json {
                println!("{}", serde_json::Value::Array(list));
            } else {
                for item in &list {
                    let default = if item["default"] == true { " (default)" } else { "" };
                    println!("{:<22} {}{}", item["name"].as_str().unwrap_or(""), item["description"].as_str().unwrap_or(""), default);
                }
            }
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
