//! The run log's documented schema (docs/scenarios.md, "Run logs") against the code and against
//! the logs of every built-in scenario.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use embodied_system::scenario::BUILTIN_SCENARIOS;
use embodied_system::system::{RunArgs, RunOptions, run_scenario};
use serde_json::Value;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

type Schema = BTreeMap<String, BTreeSet<String>>;

/// `kind` → field names, from the events table of docs/scenarios.md.
fn documented() -> Schema {
    let text = std::fs::read_to_string(root().join("docs/scenarios.md")).unwrap();
    let section = &text[text.find("### Events").expect("an Events section")..];
    let mut out = Schema::new();
    for row in section.lines().filter(|l| l.starts_with("| `") && !l.starts_with("| `kind`")) {
        let cells: Vec<&str> = row.split(" | ").collect();
        let kind = cells[0].trim_start_matches("| ").trim_matches('`').to_string();
        let fields = cells[1]
            .split("; ")
            .filter_map(|f| f.strip_prefix('`').and_then(|f| f.split('`').next()))
            .map(str::to_string)
            .collect();
        assert!(out.insert(kind.clone(), fields).is_none(), "`{kind}` twice in the table");
    }
    assert!(!out.is_empty(), "no rows in the events table");
    out
}

/// `kind` → field names, from the variants of `Event` in executor/src/event.rs.
fn in_code() -> Schema {
    let text = std::fs::read_to_string(root().join("executor/src/event.rs")).unwrap();
    let body = &text[text.find("pub enum Event {").unwrap()..];
    let body = &body[..body.find("\n}\n").unwrap()];
    let mut out = Schema::new();
    let mut current: Option<String> = None;
    for line in body.lines().skip(1).map(str::trim) {
        if line.starts_with("///") || line.starts_with("#[") || line.is_empty() {
            continue;
        }
        if line.starts_with('}') {
            current = None;
        } else if let Some(name) = current.as_ref().and_then(|_| line.split(':').next())
            && line.contains(':')
        {
            out.get_mut(current.as_ref().unwrap()).unwrap().insert(name.trim().to_string());
        } else {
            let name = line.trim_end_matches([',', '{', ' ']);
            let mut kind = String::new();
            for (i, c) in name.chars().enumerate() {
                if c.is_ascii_uppercase() && i > 0 {
                    kind.push('_');
                }
                kind.push(c.to_ascii_lowercase());
            }
            out.insert(kind.clone(), BTreeSet::new());
            if line.ends_with('{') {
                current = Some(kind);
            }
        }
    }
    out
}

#[test]
fn the_events_table_lists_every_event_and_its_fields() {
    let (doc, code) = (documented(), in_code());
    assert!(code.contains_key("plan_landed") && code["plan_landed"].contains("planning_ms"), "{code:?}");
    for (kind, fields) in &code {
        assert_eq!(doc.get(kind), Some(fields), "event `{kind}`: docs/scenarios.md says {:?}", doc.get(kind));
    }
    for kind in doc.keys() {
        assert!(code.contains_key(kind), "docs/scenarios.md lists `{kind}`, which the code does not have");
    }
}

#[test]
fn every_built_in_scenario_logs_what_the_docs_describe() {
    let doc = documented();
    let dir = common::TempDir::new("schema");
    let mut seen = BTreeSet::new();
    for (name, _) in BUILTIN_SCENARIOS {
        let log = dir.join(format!("{name}.jsonl"));
        let options = RunOptions { duration: Some(6.0), ..RunOptions::default() };
        let args = RunArgs { scenario: name.to_string(), options, log: Some(log.clone()), ..RunArgs::default() };
        run_scenario(&args).unwrap();
        let text = std::fs::read_to_string(&log).unwrap();
        let lines: Vec<Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        let header = &lines[0]["header"];
        for key in ["format", "generator", "scenario", "scenario_hash", "seed", "step_s", "duration_s", "agents"] {
            assert!(header.get(key).is_some(), "{name}: header has no `{key}`");
        }
        assert_eq!(header["format"], "embodied-log/2");
        let summary = &lines.last().unwrap()["summary"];
        for key in ["scenario", "seed", "clock", "steps", "simulated_s", "agents", "events", "failure"] {
            assert!(summary.get(key).is_some(), "{name}: summary has no `{key}`");
        }
        assert!(summary.get("wall_s").is_none(), "{name}: a wall-clock figure in the log");
        for step in &lines[1..lines.len() - 1] {
            for (agent, record) in step["agents"].as_object().unwrap() {
                for key in ["q", "qd", "behaviour", "events"] {
                    assert!(record.get(key).is_some(), "{name}: step {} agent {agent}: no `{key}`", step["step"]);
                }
                for event in record["events"].as_array().unwrap() {
                    let kind = event["kind"].as_str().unwrap();
                    let fields = doc.get(kind).unwrap_or_else(|| panic!("{name}: `{kind}` is not documented"));
                    for field in event.as_object().unwrap().keys().filter(|k| *k != "kind") {
                        assert!(fields.contains(field), "{name}: `{kind}` has `{field}`, not documented");
                    }
                    seen.insert(kind.to_string());
                }
            }
        }
    }
    // The built-in scenarios exercise the common events.
    for kind in ["plan_requested", "plan_landed", "goal_reached", "granted", "grasp", "release"] {
        assert!(seen.contains(kind), "no built-in scenario logs `{kind}`: {seen:?}");
    }
}
