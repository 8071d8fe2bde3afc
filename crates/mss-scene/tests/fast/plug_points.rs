//! Loads, region selectors and occupancy rules are resolved by name in the
//! registry, like obstacle shapes: what a program registers is used like a
//! built-in (an entry that rebuilds a built-in gives bitwise its run), the
//! built-ins are reachable by the same names, and unknown names are refused
//! with the key and the known names.

use std::sync::Arc;

use mss_scene::hexmesh::voxelize::OccupancyRule;
use mss_scene::mss_core::Vec3;
use mss_scene::mss_core::loads::{Load, NodalForce};
use mss_scene::{Cancel, Job, JobError, Registry, SceneInput, no_progress};

const BASE: &str = "[mesh]\npath = \"builtin:critter\"\n[material]\nyoung = 1.0e5\n\
                    poisson = 0.3\ndensity = 1000.0\n[[fixed]]\nkind = \"lowest_layer\"\n\
                    [solver]\nduration = 0.02\n[output]\nevery_time = 0.01\n";

fn prepare(extra: &str, registry: Registry) -> Result<Job, JobError> {
    let input = SceneInput::from_toml(&format!("{BASE}{extra}"), "plug.toml").unwrap();
    Job::prepare(input, registry, &no_progress)
}

/// The last lattice frame of a run, as bytes.
fn run(extra: &str, registry: Registry) -> Vec<u8> {
    let job = prepare(extra, registry).unwrap();
    let dir = tempfile::tempdir().unwrap();
    job.run(dir.path(), &no_progress, &Cancel::new()).unwrap();
    std::fs::read(dir.path().join("lattice_0002.vtu")).unwrap()
}

/// A wind of `push` newtons on every node: the built-in force with
/// `per_node = true`, written by a program.
fn wind(
    table: &mss_scene::kind_table::KindTable,
    model: &mss_scene::mss_core::Model,
) -> Result<Box<dyn Load>, mss_scene::mss_core::loads::LoadError> {
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Keys {
        push: [f64; 3],
    }
    let keys: Keys = table.keys_as()?;
    Ok(Box::new(NodalForce {
        nodes: (0..model.num_nodes() as u32).collect(),
        per_node: Vec3::new(keys.push[0], keys.push[1], keys.push[2]),
    }))
}

#[test]
fn a_registered_load_is_used_by_name() {
    let push = "[0.0, 0.01, 0.0]";
    let builtin = run(
        &format!(
            "[[loads.forces]]\nselect = {{ kind = \"box\", min = [-9, -9, -9], max = [9, 9, 9] }}\n\
             force = {push}\nper_node = true\n"
        ),
        Registry::default(),
    );
    let mut registry = Registry::default();
    registry.loads.register("wind", Arc::new(wind));
    let custom = run(
        &format!("[[loads.custom]]\nkind = \"wind\"\npush = {push}\n"),
        registry,
    );
    assert!(
        builtin == custom,
        "the registered wind differs from the force"
    );
    // The built-in by kind is the built-in table.
    let by_kind = run(
        &format!(
            "[[loads.custom]]\nkind = \"force\"\n\
             select = {{ kind = \"box\", min = [-9, -9, -9], max = [9, 9, 9] }}\n\
             force = {push}\nper_node = true\n"
        ),
        Registry::default(),
    );
    assert!(builtin == by_kind);
    let still = run("", Registry::default());
    assert!(
        still != builtin,
        "the load moves nothing: the test shows nothing"
    );

    for (extra, words) in [
        (
            "[[loads.custom]]\nkind = \"wind\"\npush = [0, 0, 1]\n",
            "unknown load kind (known: gravity, force, traction, drag)",
        ),
        (
            "[[loads.custom]]\nkind = \"gravity\"\ng = [0, 0]\n",
            "gravity",
        ),
        (
            "[[loads.custom]]\nkind = \"gravity\"\ng = [0, 0, 1]\ncolour = 1\n",
            "colour",
        ),
    ] {
        let text = prepare(extra, Registry::default())
            .err()
            .unwrap_or_else(|| panic!("{extra}: accepted"))
            .to_string();
        assert!(
            text.contains("[[loads.custom]] #1") && text.contains(words),
            "{extra}: {text}"
        );
    }
}

#[test]
fn a_registered_region_selector_is_used_by_name() {
    let region = "young = 1.0e6\ndensity = 500.0\n";
    let builtin = run(
        &format!(
            "[[regions]]\nselect = {{ kind = \"box\", min = [0, 0, 0], max = [1, 1, 0.5], \
             relative = true }}\n{region}"
        ),
        Registry::default(),
    );
    let mut registry = Registry::default();
    // The lower half of the bounding box, by a name of its own.
    registry.regions.register(
        "lower-half",
        Arc::new(|_, context| {
            let (lo, hi) = (context.bounds.min, context.bounds.max);
            let mid = lo[2] + 0.5 * (hi[2] - lo[2]);
            Ok(Box::new(move |p: [f64; 3]| {
                (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]) && p[2] <= mid
            }))
        }),
    );
    let custom = run(
        &format!("[[regions]]\nselect = {{ kind = \"lower-half\" }}\n{region}"),
        registry,
    );
    assert!(
        builtin == custom,
        "the registered selector differs from the box"
    );
    assert!(
        run("", Registry::default()) != builtin,
        "the region changes nothing: the test shows nothing"
    );
    let text = prepare(
        &format!("[[regions]]\nselect = {{ kind = \"lower-half\" }}\n{region}"),
        Registry::default(),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(
        text.contains("[[regions]] #1") && text.contains("known: box, sphere, mesh"),
        "{text}"
    );
}

#[test]
fn a_registered_occupancy_rule_is_used_by_name() {
    let cells =
        |extra: &str, registry: Registry| prepare(extra, registry).unwrap().lattice().num_cells();
    let mut registry = Registry::default();
    // The fraction rule sampled more finely.
    registry.occupancy.register(
        "fraction-fine",
        Arc::new(|threshold| OccupancyRule::Fraction {
            threshold,
            samples_per_axis: 8,
        }),
    );
    let fine = cells(
        "[voxelize]\ncells = 8\nrule = \"fraction-fine\"\nfraction = 0.9\n",
        registry.clone(),
    );
    let any = cells("[voxelize]\ncells = 8\nrule = \"any\"\n", registry);
    let centre = cells("[voxelize]\ncells = 8\n", Registry::default());
    // Nine tenths inside keeps fewer cells than the centre rule, which
    // keeps fewer than any overlap.
    assert!(fine < centre && centre < any, "{fine} {centre} {any}");
    let err = prepare("[voxelize]\nrule = \"most\"\n", Registry::default())
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("[voxelize] rule")
            && err.contains("\"most\"")
            && err.contains("known: centre, any, fraction"),
        "{err}"
    );
}
