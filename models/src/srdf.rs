//! SRDF (MoveIt's Semantic Robot Description Format): planning groups, named group states,
//! end effectors and self-collision pairs to ignore.
//!
//! Only what a planner needs is read: `<group>` (chains, joints, links, subgroups),
//! `<group_state>`, `<end_effector>` and `<disable_collisions>`. Other elements
//! (`<virtual_joint>`, `<passive_joint>`, `<link_sphere_approximation>`, ...) are ignored.
//! Every reference to a group inside the file (a subgroup, a group state's group, an end
//! effector's group) must name a group of the file; errors name `file:line:column`.
//!
//! ```
//! use std::path::Path;
//! use embodied_models::srdf::parse_srdf;
//! let text = r#"<robot name="r"><group name="arm"><chain base_link="a" tip_link="c"/></group>
//!               <disable_collisions link1="a" link2="b" reason="Adjacent"/></robot>"#;
//! let srdf = parse_srdf(text, Path::new("r.srdf")).unwrap();
//! assert_eq!(srdf.groups[0].chains, vec![("a".to_string(), "c".to_string())]);
//! assert_eq!(srdf.disabled, vec![("a".to_string(), "b".to_string())]);
//! ```

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::error::ModelError;
use crate::robot::Robot;
use crate::urdf::Xml;

/// The content of an SRDF file.
#[derive(Debug, Clone, Default)]
pub struct Srdf {
    /// The `name` of the `<robot>` element (normally the URDF's robot name; not checked).
    pub robot_name: String,
    pub groups: Vec<Group>,
    /// `<disable_collisions link1 link2>` pairs, in file order.
    pub disabled: Vec<(String, String)>,
    pub group_states: Vec<GroupState>,
    pub end_effectors: Vec<SrdfEndEffector>,
    /// The file the SRDF was read from (used in error messages).
    pub file: PathBuf,
}

/// A planning group: the union of its chains, joints, links and subgroups.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Group {
    pub name: String,
    /// `(base_link, tip_link)` of each `<chain>`.
    pub chains: Vec<(String, String)>,
    pub joints: Vec<String>,
    pub links: Vec<String>,
    pub subgroups: Vec<String>,
}

/// A named configuration of a group (`<group_state name group>`).
#[derive(Debug, Clone, PartialEq)]
pub struct GroupState {
    pub name: String,
    pub group: String,
    /// `(joint name, value)` in file order.
    pub values: Vec<(String, f64)>,
    /// Line of the `<group_state>` element in [`Srdf::file`].
    pub line: u32,
}

/// An `<end_effector name parent_link group [parent_group]>`.
#[derive(Debug, Clone, PartialEq)]
pub struct SrdfEndEffector {
    pub name: String,
    pub parent_link: String,
    pub group: String,
    pub parent_group: Option<String>,
    /// Line of the `<end_effector>` element in [`Srdf::file`].
    pub line: u32,
}

/// Read and parse an SRDF file.
pub fn load_srdf(path: &Path) -> Result<Srdf, ModelError> {
    let text = std::fs::read_to_string(path).map_err(|source| ModelError::Io { file: path.to_path_buf(), source })?;
    parse_srdf(&text, path)
}

/// Parse SRDF text; `file` is used in error messages.
pub fn parse_srdf(text: &str, file: &Path) -> Result<Srdf, ModelError> {
    let doc = Xml::parse(text, file)?;
    let x = &doc;
    let root = doc.doc.root_element();
    if root.tag_name().name() != "robot" {
        return Err(x.err(root, format!("expected a <robot> root element, found <{}>", root.tag_name().name())));
    }
    let mut srdf = Srdf {
        robot_name: x.attr(root, "name", "the robot's name")?.to_string(),
        file: file.to_path_buf(),
        ..Srdf::default()
    };
    // Group references are checked once every group is known: (node, referenced group name).
    let mut references = Vec::new();
    for node in root.children().filter(|n| n.is_element()) {
        match node.tag_name().name() {
            "group" => {
                let name = x.attr(node, "name", "the group's name")?.to_string();
                if srdf.groups.iter().any(|g| g.name == name) {
                    return Err(x.err(node, format!("a second group named `{name}` (group names must be unique)")));
                }
                let mut group = Group { name, ..Group::default() };
                for member in node.children().filter(|n| n.is_element()) {
                    match member.tag_name().name() {
                        "chain" => group.chains.push((
                            x.attr(member, "base_link", "the chain's base link name")?.to_string(),
                            x.attr(member, "tip_link", "the chain's tip link name")?.to_string(),
                        )),
                        "joint" => group.joints.push(x.attr(member, "name", "a joint name")?.to_string()),
                        "link" => group.links.push(x.attr(member, "name", "a link name")?.to_string()),
                        "group" => {
                            let sub = x.attr(member, "name", "a group name")?.to_string();
                            references.push((member, sub.clone()));
                            group.subgroups.push(sub);
                        }
                        other => {
                            return Err(x.err(
                                member,
                                format!(
                                    "unexpected <{other}> in <group> (expected <chain>, <joint>, <link> or <group>)"
                                ),
                            ));
                        }
                    }
                }
                srdf.groups.push(group);
            }
            "group_state" => {
                let name = x.attr(node, "name", "the state's name")?.to_string();
                let group = x.attr(node, "group", "the name of a group")?.to_string();
                references.push((node, group.clone()));
                let mut values = Vec::new();
                for j in node.children().filter(|n| n.is_element() && n.tag_name().name() == "joint") {
                    let joint = x.attr(j, "name", "a joint name")?.to_string();
                    let value = x.number(j, "value", "one number (radians or metres)")?;
                    values.push((joint, value));
                }
                srdf.group_states.push(GroupState { name, group, values, line: x.line(node) });
            }
            "end_effector" => {
                let group = x.attr(node, "group", "the name of the end effector's group")?.to_string();
                references.push((node, group.clone()));
                let parent_group = match node.attribute("parent_group") {
                    Some(g) => {
                        references.push((node, g.to_string()));
                        Some(g.to_string())
                    }
                    None => None,
                };
                srdf.end_effectors.push(SrdfEndEffector {
                    name: x.attr(node, "name", "the end effector's name")?.to_string(),
                    parent_link: x.attr(node, "parent_link", "the link the end effector is attached to")?.to_string(),
                    group,
                    parent_group,
                    line: x.line(node),
                });
            }
            "disable_collisions" => srdf.disabled.push((
                x.attr(node, "link1", "a link name")?.to_string(),
                x.attr(node, "link2", "a link name")?.to_string(),
            )),
            _ => {}
        }
    }
    for (node, name) in references {
        if !srdf.groups.iter().any(|g| g.name == name) {
            let known: Vec<&str> = srdf.groups.iter().map(|g| g.name.as_str()).collect();
            return Err(x.err(
                node,
                format!(
                    "unknown group `{name}` (expected one of the groups defined in the file: {})",
                    known.join(", ")
                ),
            ));
        }
    }
    Ok(srdf)
}

impl Srdf {
    /// A group by name.
    pub fn group(&self, name: &str) -> Option<&Group> {
        self.groups.iter().find(|g| g.name == name)
    }

    /// A group state by name (the first if several groups use the name).
    pub fn group_state(&self, name: &str) -> Option<&GroupState> {
        self.group_states.iter().find(|s| s.name == name)
    }

    /// The active joints (degrees of freedom of `robot`: not fixed, not mimic) of a group, in
    /// the robot's `q` order.
    ///
    /// Membership follows MoveIt: a `<chain>` contributes the joints on the tree path from its
    /// base link down to its tip link (the base link must be an ancestor of the tip); a
    /// `<joint>` itself; a `<link>` its parent joint; a `<group>` its own joints, recursively.
    pub fn group_joints(&self, robot: &Robot, group: &str) -> Result<Vec<String>, ModelError> {
        let mut joints = BTreeSet::new();
        let mut stack = Vec::new();
        self.collect_joints(robot, group, &mut stack, &mut joints)?;
        let mut dofs: Vec<usize> = joints.into_iter().filter_map(|j| robot.joints()[j].dof_index).collect();
        dofs.sort_unstable();
        dofs.dedup();
        Ok(dofs.into_iter().map(|d| robot.dof_joint(d).name.clone()).collect())
    }

    /// Like [`Srdf::group_joints`] but the indices of the degrees of freedom in `q`.
    pub fn group_dofs(&self, robot: &Robot, group: &str) -> Result<Vec<usize>, ModelError> {
        let names = self.group_joints(robot, group)?;
        Ok(names.iter().filter_map(|n| robot.joint_index(n).and_then(|j| robot.joints()[j].dof_index)).collect())
    }

    fn collect_joints<'s>(
        &'s self,
        robot: &Robot,
        group: &'s str,
        stack: &mut Vec<&'s str>,
        out: &mut BTreeSet<usize>,
    ) -> Result<(), ModelError> {
        let invalid = |message: String| ModelError::Invalid { robot: robot.name().to_string(), message };
        let Some(g) = self.group(group) else {
            let known: Vec<&str> = self.groups.iter().map(|g| g.name.as_str()).collect();
            return Err(invalid(format!(
                "SRDF {} has no group `{group}` (expected one of: {})",
                self.file.display(),
                known.join(", ")
            )));
        };
        if stack.contains(&group) {
            return Err(invalid(format!(
                "SRDF {}: group `{group}` contains itself through its subgroups ({} -> {group})",
                self.file.display(),
                stack.join(" -> ")
            )));
        }
        stack.push(group);
        let link = |name: &str| {
            robot.link_index(name).ok_or_else(|| ModelError::NoSuchName {
                robot: robot.name().to_string(),
                what: "link",
                name: name.to_string(),
            })
        };
        for (base, tip) in &g.chains {
            let (base_i, tip_i) = (link(base)?, link(tip)?);
            let chain = robot.chain_to(tip_i);
            // Joints below the base link: those after the base link's own parent joint.
            let start = match robot.links()[base_i].parent_joint {
                None => Some(0),
                Some(bj) => chain.iter().position(|&j| j == bj).map(|p| p + 1),
            };
            let Some(start) = start else {
                return Err(invalid(format!(
                    "SRDF {}: group `{group}` has a chain from `{base}` to `{tip}`, but `{base}` is not an ancestor of `{tip}`",
                    self.file.display()
                )));
            };
            out.extend(&chain[start..]);
        }
        for j in &g.joints {
            let ji = robot.joint_index(j).ok_or_else(|| ModelError::NoSuchName {
                robot: robot.name().to_string(),
                what: "joint",
                name: j.clone(),
            })?;
            out.insert(ji);
        }
        for l in &g.links {
            if let Some(pj) = robot.links()[link(l)?].parent_joint {
                out.insert(pj);
            }
        }
        for sub in &g.subgroups {
            self.collect_joints(robot, sub, stack, out)?;
        }
        stack.pop();
        Ok(())
    }
}

/// Disable self-collision checking for every `<disable_collisions>` pair of `srdf` whose two
/// links exist in `robot` (pairs naming other links are skipped, as MoveIt does).
pub fn apply_srdf(robot: &mut Robot, srdf: &Srdf) {
    for (a, b) in &srdf.disabled {
        if let (Some(a), Some(b)) = (robot.link_index(a), robot.link_index(b)) {
            robot.disable_pair(a, b);
        }
    }
}
