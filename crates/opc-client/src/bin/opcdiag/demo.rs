//! `opcdiag demo`: a tour of ServerCTOPC's demo plant Wytwornia_Kwasu (a sulphuric acid
//! plant, demo/wytwornia_kwasu): the server status, the first levels of the plant tree,
//! then live values of a handful of process variables until Ctrl+C or `--for`.

use crate::cli::{EXIT_FAILED, EXIT_OK};
use crate::text;
use crate::win::{offset, Session, Subscription};
use ctopc_com::interfaces::{OPC_PROPERTY_DESCRIPTION, OPC_PROPERTY_EU_UNITS};
use ctopc_core::Value;

/// The variables the demo follows (item IDs of the demo database): tank levels,
/// temperatures, flows and a pump of the plant's sections.
pub const DEMO_ITEMS: &[&str] = &[
    "KW_A000", // LI101  liquid sulphur level, tank Z101 (m)
    "KW_A001", // TI101  sulphur temperature, tank Z101 (°C)
    "KW_A020", // FI106  liquid sulphur flow to the furnace (t/h)
    "KW_D002", // MS105A sulphur pump P105A running (0/1)
    "KW_A014", // II105A motor current of pump P105A (A)
    "KW_A100", // TI201  furnace burner zone temperature (°C)
    "KW_A115", // FI202  air flow to the furnace (kNm3/h)
    "KW_A400", // LI401  acid level, storage tank Z401 (m)
];

/// Levels of the plant tree shown.
const TREE_DEPTH: usize = 2;

pub fn run(s: &Session, for_secs: Option<f64>) -> Result<u8, String> {
    say!("=== ServerCTOPC demo: Wytwornia_Kwasu, a sulphuric acid plant ===");
    say!();
    s.status()?;
    say!();

    say!("Plant tree (first {TREE_DEPTH} levels):");
    let mut lines = Vec::new();
    s.tree(0, Some(TREE_DEPTH), &mut lines)?;
    for l in text::render_tree(&lines).lines() {
        say!("  {l}");
    }
    say!();

    let items: Vec<String> = DEMO_ITEMS.iter().map(|s| s.to_string()).collect();
    let sub = Subscription::start(s, &items, "", 1000).map_err(|e| {
        format!("{e}\nthe demo needs ServerCTOPC with the Wytwornia_Kwasu demo database (its embedded default, or `cargo xtask demo`)")
    })?;
    let mut units: Vec<String> = Vec::with_capacity(items.len());
    say!("Variables:");
    for item in &items {
        let (desc, unit) = describe(s, item);
        say!(
            "  {}  {}{}",
            text::pad(item, 7),
            desc,
            if unit.is_empty() {
                String::new()
            } else {
                format!(" [{unit}]")
            }
        );
        units.push(unit);
    }
    for (name, err) in &sub.failed {
        say!("  {name}: not available: {}", s.error_text(*err));
    }
    say!();
    let until = match for_secs {
        Some(secs) => format!("for {secs} s"),
        None => "press Ctrl+C to stop".into(),
    };
    say!(
        "Live values (update rate {} ms, {until}):",
        sub.revised_rate
    );
    let n = sub.run(for_secs, None, |name, r| {
        let unit = items
            .iter()
            .position(|i| i == name)
            .and_then(|i| units.get(i))
            .map_or("", String::as_str);
        let value = if r.error.is_err() {
            format!("error {}", s.error_text(r.error))
        } else {
            format!("{} {unit}", text::value_rounded(&r.value, 2))
        };
        // Short enough for an 80-column console: the quality without its hex bits.
        say!(
            "  {}  {}  {}  {}",
            text::local_time_of_day(r.timestamp, offset(r.timestamp)),
            text::pad(name, 7),
            text::pad(&value, 15),
            ctopc_core::Quality(r.quality)
        );
    });
    sub.stop(s);
    say!();
    say!("{n} value change(s) received.");
    Ok(if n == 0 { EXIT_FAILED } else { EXIT_OK })
}

/// The item's description and engineering unit (properties 101 and 100), empty if the
/// server has none.
fn describe(s: &Session, item: &str) -> (String, String) {
    let text_of = |v: &Value| match v {
        Value::Bstr(t) => t.clone(),
        _ => String::new(),
    };
    match s
        .server
        .get_item_properties(item, &[OPC_PROPERTY_DESCRIPTION, OPC_PROPERTY_EU_UNITS])
    {
        Ok((_, v)) if v.len() == 2 => (text_of(&v[0].0), text_of(&v[1].0)),
        _ => (String::new(), String::new()),
    }
}
