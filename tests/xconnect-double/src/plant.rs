//! The double's scriptable plant, pure and deterministic: variables with a value, a
//! quality and a timestamp, the switches that make calls fail or hang and set the
//! reported ServerState, and the rules of each method. Time is an argument (an OLE
//! Automation date, local time); the COM object (`server.rs`) supplies it.
//!
//! The option string (`Init`, or `LoadChannel` of the known channel with the environment
//! variable `XCONNECT_DOUBLE_OPTIONS`): `Key=Value` pairs separated by `;`, keys
//! case-insensitive, lists separated by `,`; keys other than these are ignored (the
//! original's channel options):
//! - `Vars=A,B,...`: the variables (default [`DEFAULT_VARS`], the demo plant's first
//!   four), each starting at value 10 × its position + 10, quality good;
//! - `PeriodMs=N` (10..=60000, default 100): the timer period while `Active` is true;
//!   each tick adds 1 to every variable and stamps it good with the tick's time;
//! - `State=N` (1..=5, default 1): the ServerState reported;
//! - `Fail=M1,M2`: these methods fail (Read, Write, WriteEx, SetItemActive) with the
//!   error codes of the original ([`NET_ANSWER_TIMEOUT`], [`WRITE_ERROR`]) and a text;
//! - `Hang=M1,M2` and `HangMs=N` (1..=60000, default 200): these methods take `HangMs`
//!   before they answer.

use ctopc_core::Value;

/// The channel `LoadChannel` knows (the demo application's).
pub const CHANNEL: &str = "Demo_Wytwornia_Kwasu";
/// The default variables: the demo plant's first four (`demo/wytwornia_kwasu`).
pub const DEFAULT_VARS: [&str; 4] = ["KW_A000", "KW_A001", "KW_A002", "KW_A003"];

// The original's error codes (the AsixConnect manual, §8) and the standard ones used.
pub const NET_INIT: i32 = 0xC004_8100_u32 as i32;
pub const NET_FIND_SERVER_NOT_FOUND: i32 = 0xC004_8105_u32 as i32;
pub const NET_ANSWER_TIMEOUT: i32 = 0xC004_810B_u32 as i32;
pub const ITEM_UNKNOWN: i32 = 0xC004_8120_u32 as i32;
pub const WRITE_ERROR: i32 = 0xC004_8128_u32 as i32;
pub const E_INVALIDARG: i32 = 0x8007_0057_u32 as i32;
pub const DISP_E_TYPEMISMATCH: i32 = 0x8002_0005_u32 as i32;

/// Quality of a good value, and of a cache read of an inactive variable (Bad, out of
/// service).
pub const GOOD: u16 = 0xC0;
pub const BAD_OUT_OF_SERVICE: u16 = 0x1C;

/// A failed call: the code (an HRESULT) and the text the client gets through IErrorInfo.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fault {
    pub code: i32,
    pub text: String,
}

fn fault(code: i32, text: impl Into<String>) -> Fault {
    Fault {
        code,
        text: text.into(),
    }
}

/// The parsed switches of an option string.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    pub vars: Vec<String>,
    pub period_ms: u32,
    pub state: i32,
    pub fail: Vec<String>,
    pub hang: Vec<String>,
    pub hang_ms: u32,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            vars: DEFAULT_VARS.iter().map(|s| s.to_string()).collect(),
            period_ms: 100,
            state: 1,
            fail: Vec::new(),
            hang: Vec::new(),
            hang_ms: 200,
        }
    }
}

fn number(key: &str, value: &str, range: std::ops::RangeInclusive<u32>) -> Result<u32, Fault> {
    value
        .trim()
        .parse::<u32>()
        .ok()
        .filter(|n| range.contains(n))
        .ok_or_else(|| {
            fault(
                E_INVALIDARG,
                format!(
                    "option {key}={value}: a number from {} to {} expected",
                    range.start(),
                    range.end()
                ),
            )
        })
}

fn list(value: &str) -> Vec<String> {
    value
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(str::to_owned)
        .collect()
}

impl Options {
    /// Parses an option string (module documentation).
    pub fn parse(text: &str) -> Result<Options, Fault> {
        let mut o = Options::default();
        for pair in text.split(';').map(str::trim).filter(|p| !p.is_empty()) {
            let Some((key, value)) = pair.split_once('=') else {
                return Err(fault(
                    E_INVALIDARG,
                    format!("option {pair:?}: Key=Value expected"),
                ));
            };
            let key = key.trim();
            match key.to_ascii_lowercase().as_str() {
                "vars" => {
                    o.vars = list(value);
                    if o.vars.is_empty() {
                        return Err(fault(E_INVALIDARG, "option Vars: no variable named"));
                    }
                }
                "periodms" => o.period_ms = number(key, value, 10..=60_000)?,
                "state" => o.state = number(key, value, 1..=5)? as i32,
                "fail" => o.fail = list(value),
                "hang" => o.hang = list(value),
                "hangms" => o.hang_ms = number(key, value, 1..=60_000)?,
                _ => {}
            }
        }
        Ok(o)
    }
}

#[derive(Debug, Clone, PartialEq)]
struct Var {
    name: String,
    value: f64,
    quality: u16,
    timestamp: f64,
    active: bool,
}

/// One variable's reading: value, quality, timestamp (OLE date, local time).
#[derive(Debug, Clone, PartialEq)]
pub struct Reading {
    pub item: String,
    pub value: Value,
    pub quality: u16,
    pub timestamp: f64,
}

/// The plant behind one object.
#[derive(Debug, Clone, PartialEq)]
pub struct Plant {
    options: Option<Options>,
    vars: Vec<Var>,
    /// The `Active` property: DataChange events and the timer only while true.
    pub active: bool,
}

/// The data sources of `Read`.
pub const DS_CACHE: i64 = 1;
pub const DS_DEVICE: i64 = 2;
pub const DS_DRIVER: i64 = 3;

/// An integer argument (any integer VARIANT type, or a real with no fraction).
pub fn integer(v: &Value) -> Option<i64> {
    Some(match v {
        Value::I1(x) => i64::from(*x),
        Value::UI1(x) => i64::from(*x),
        Value::I2(x) => i64::from(*x),
        Value::UI2(x) => i64::from(*x),
        Value::I4(x) => i64::from(*x),
        Value::UI4(x) => i64::from(*x),
        Value::I8(x) => *x,
        Value::UI8(x) => i64::try_from(*x).ok()?,
        Value::R4(x) if x.fract() == 0.0 => *x as i64,
        Value::R8(x) if x.fract() == 0.0 => *x as i64,
        _ => return None,
    })
}

/// A value written: integer or real (the original's rule), as f64.
pub fn numeric(v: &Value) -> Option<f64> {
    match v {
        Value::R4(x) => Some(f64::from(*x)),
        Value::R8(x) => Some(*x),
        other => integer(other).map(|i| i as f64),
    }
}

/// A boolean argument (VT_BOOL, or an integer: non-zero is true).
pub fn boolean(v: &Value) -> Option<bool> {
    match v {
        Value::Bool(b) => Some(*b),
        other => integer(other).map(|i| i != 0),
    }
}

fn text(v: &Value, what: &str) -> Result<String, Fault> {
    match v {
        Value::Bstr(s) => Ok(s.clone()),
        _ => Err(fault(
            DISP_E_TYPEMISMATCH,
            format!("{what}: a string expected"),
        )),
    }
}

impl Default for Plant {
    fn default() -> Self {
        Plant::new()
    }
}

impl Plant {
    /// Not initialised: ServerState 3 (no configuration) until `Init` or `LoadChannel`.
    pub fn new() -> Plant {
        Plant {
            options: None,
            vars: Vec::new(),
            active: false,
        }
    }

    /// `Init InitString` (also a re-initialisation: variables start over, inactive).
    pub fn init(&mut self, init: &Value, now: f64) -> Result<(), Fault> {
        let options = Options::parse(&text(init, "InitString")?)?;
        self.apply(options, now);
        Ok(())
    }

    /// `LoadChannel ChannelName` with the options `env_options` (the environment's).
    pub fn load_channel(
        &mut self,
        channel: &Value,
        env_options: &str,
        now: f64,
    ) -> Result<(), Fault> {
        let name = text(channel, "ChannelName")?;
        if name != CHANNEL {
            return Err(fault(
                NET_FIND_SERVER_NOT_FOUND,
                format!("NetFindServer_NotFound: no asix server offers channel {name:?}"),
            ));
        }
        let options = Options::parse(env_options)?;
        self.apply(options, now);
        Ok(())
    }

    fn apply(&mut self, options: Options, now: f64) {
        self.vars = options
            .vars
            .iter()
            .enumerate()
            .map(|(i, name)| Var {
                name: name.clone(),
                value: 10.0 * (i as f64) + 10.0,
                quality: GOOD,
                timestamp: now,
                active: false,
            })
            .collect();
        self.options = Some(options);
    }

    pub fn options(&self) -> Option<&Options> {
        self.options.as_ref()
    }

    /// The ServerState property: 3 (no configuration) before initialisation, else the
    /// `State` option.
    pub fn server_state(&self) -> i32 {
        self.options.as_ref().map_or(3, |o| o.state)
    }

    /// How long `method` hangs before answering (`Hang`/`HangMs`), if it does.
    pub fn hang_ms(&self, method: &str) -> Option<u32> {
        let o = self.options.as_ref()?;
        o.hang
            .iter()
            .any(|m| m.eq_ignore_ascii_case(method))
            .then_some(o.hang_ms)
    }

    /// The checks every data method makes first: initialised, and not switched to fail.
    fn ready(&self, method: &str) -> Result<(), Fault> {
        let Some(o) = &self.options else {
            return Err(fault(
                NET_INIT,
                format!("NetInit: {method} before LoadChannel or Init"),
            ));
        };
        if o.fail.iter().any(|m| m.eq_ignore_ascii_case(method)) {
            return Err(if method.starts_with("Write") {
                fault(
                    WRITE_ERROR,
                    format!("WriteError: {method} failed (switch Fail={method})"),
                )
            } else {
                fault(
                    NET_ANSWER_TIMEOUT,
                    format!("NetAnswerTimeout: {method} failed (switch Fail={method})"),
                )
            });
        }
        Ok(())
    }

    fn var(&mut self, item: &Value) -> Result<&mut Var, Fault> {
        let name = text(item, "ItemID")?;
        self.vars
            .iter_mut()
            .find(|v| v.name == name)
            .ok_or_else(|| fault(ITEM_UNKNOWN, format!("ItemUnknown: no variable {name:?}")))
    }

    /// `Read DataSource, ItemID, ...`: the value, quality and timestamp. A cache read of an
    /// inactive variable is Bad (out of service), with no value, stamped `now`.
    pub fn read(&mut self, source: &Value, item: &Value, now: f64) -> Result<Reading, Fault> {
        self.ready("Read")?;
        let source = integer(source).filter(|s| (DS_CACHE..=DS_DRIVER).contains(s));
        let Some(source) = source else {
            return Err(fault(
                E_INVALIDARG,
                "DataSource: 1 (dsCache), 2 (dsDevice) or 3 (dsDriver) expected",
            ));
        };
        let var = self.var(item)?;
        if source == DS_CACHE && !var.active {
            return Ok(Reading {
                item: var.name.clone(),
                value: Value::Empty,
                quality: BAD_OUT_OF_SERVICE,
                timestamp: now,
            });
        }
        Ok(reading(var))
    }

    /// `SetItemActive ItemID, ActiveState`.
    pub fn set_item_active(&mut self, item: &Value, state: &Value) -> Result<(), Fault> {
        self.ready("SetItemActive")?;
        let state = boolean(state)
            .ok_or_else(|| fault(DISP_E_TYPEMISMATCH, "ActiveState: a boolean expected"))?;
        self.var(item)?.active = state;
        Ok(())
    }

    /// `Write ItemID, Value`: good quality, stamped `now`.
    pub fn write(&mut self, item: &Value, value: &Value, now: f64) -> Result<(), Fault> {
        self.ready("Write")?;
        let value = numeric(value)
            .ok_or_else(|| fault(DISP_E_TYPEMISMATCH, "Value: integer or real expected"))?;
        let var = self.var(item)?;
        var.value = value;
        var.quality = GOOD;
        var.timestamp = now;
        Ok(())
    }

    /// `WriteEx ItemID, Value, Quality, TimeStamp`.
    pub fn write_ex(
        &mut self,
        item: &Value,
        value: &Value,
        quality: &Value,
        timestamp: &Value,
    ) -> Result<(), Fault> {
        self.ready("WriteEx")?;
        let value = numeric(value)
            .ok_or_else(|| fault(DISP_E_TYPEMISMATCH, "Value: integer or real expected"))?;
        let quality = integer(quality)
            .and_then(|q| u16::try_from(q).ok())
            .ok_or_else(|| fault(DISP_E_TYPEMISMATCH, "Quality: a 16-bit quality expected"))?;
        let timestamp = match timestamp {
            Value::Date(d) | Value::R8(d) => *d,
            _ => return Err(fault(DISP_E_TYPEMISMATCH, "TimeStamp: a date expected")),
        };
        let var = self.var(item)?;
        var.value = value;
        var.quality = quality;
        var.timestamp = timestamp;
        Ok(())
    }

    /// One timer tick at `now`: every variable goes up by 1, good, stamped `now`; returns
    /// the readings of the active ones (the DataChange events), none while `Active` is
    /// false.
    pub fn tick(&mut self, now: f64) -> Vec<Reading> {
        if !self.active {
            return Vec::new();
        }
        let mut changed = Vec::new();
        for var in &mut self.vars {
            var.value += 1.0;
            var.quality = GOOD;
            var.timestamp = now;
            if var.active {
                changed.push(reading(var));
            }
        }
        changed
    }
}

fn reading(var: &Var) -> Reading {
    Reading {
        item: var.name.clone(),
        value: Value::R8(var.value),
        quality: var.quality,
        timestamp: var.timestamp,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(x: &str) -> Value {
        Value::Bstr(x.to_owned())
    }

    #[test]
    fn options_parse_switches_and_ignore_other_keys() {
        let o =
            Options::parse("Vars=A, B;periodms=50;State=2;Fail=Read;Hang=Write;HangMs=300;Nazwa=X")
                .unwrap();
        assert_eq!(o.vars, ["A", "B"]);
        assert_eq!((o.period_ms, o.state, o.hang_ms), (50, 2, 300));
        assert_eq!(
            (o.fail.as_slice(), o.hang.as_slice()),
            (&["Read".to_owned()][..], &["Write".to_owned()][..])
        );
        assert_eq!(Options::parse("").unwrap(), Options::default());
        for bad in [
            "State=6",
            "State=0",
            "PeriodMs=x",
            "HangMs=0",
            "Vars=",
            "novalue",
        ] {
            assert_eq!(Options::parse(bad).unwrap_err().code, E_INVALIDARG, "{bad}");
        }
    }

    #[test]
    fn before_initialisation_calls_fail_and_state_is_no_config() {
        let mut p = Plant::new();
        assert_eq!(p.server_state(), 3);
        let e = p.read(&Value::I4(2), &s("KW_A000"), 1.0).unwrap_err();
        assert_eq!(e.code, NET_INIT);
        assert!(e.text.contains("Read"), "{}", e.text);
    }

    #[test]
    fn load_channel_knows_the_demo_channel_only() {
        let mut p = Plant::new();
        let e = p.load_channel(&s("Other"), "", 1.0).unwrap_err();
        assert_eq!(e.code, NET_FIND_SERVER_NOT_FOUND);
        p.load_channel(&s(CHANNEL), "State=5", 1.0).unwrap();
        assert_eq!(p.server_state(), 5);
        let r = p.read(&Value::I2(3), &s("KW_A001"), 2.0).unwrap();
        assert_eq!(
            (r.value, r.quality, r.timestamp),
            (Value::R8(20.0), GOOD, 1.0)
        );
    }

    #[test]
    fn read_sources_cache_needs_an_active_item() {
        let mut p = Plant::new();
        p.init(&s("Vars=X,Y"), 1.0).unwrap();
        let cache = p.read(&Value::I4(1), &s("Y"), 7.0).unwrap();
        assert_eq!(
            (cache.value, cache.quality, cache.timestamp),
            (Value::Empty, BAD_OUT_OF_SERVICE, 7.0)
        );
        for ds in [2, 3] {
            let r = p.read(&Value::I4(ds), &s("Y"), 7.0).unwrap();
            assert_eq!((r.value, r.quality), (Value::R8(20.0), GOOD));
        }
        p.set_item_active(&s("Y"), &Value::Bool(true)).unwrap();
        assert_eq!(
            p.read(&Value::I4(1), &s("Y"), 7.0).unwrap().value,
            Value::R8(20.0)
        );
        assert_eq!(
            p.read(&Value::I4(4), &s("Y"), 7.0).unwrap_err().code,
            E_INVALIDARG
        );
        assert_eq!(
            p.read(&Value::I4(2), &s("Z"), 7.0).unwrap_err().code,
            ITEM_UNKNOWN
        );
    }

    #[test]
    fn writes_store_value_quality_and_time() {
        let mut p = Plant::new();
        p.init(&s(""), 1.0).unwrap();
        p.write(&s("KW_A000"), &Value::I2(42), 3.0).unwrap();
        let r = p.read(&Value::I4(2), &s("KW_A000"), 4.0).unwrap();
        assert_eq!(
            (r.value, r.quality, r.timestamp),
            (Value::R8(42.0), GOOD, 3.0)
        );
        p.write_ex(
            &s("KW_A000"),
            &Value::R4(1.5),
            &Value::I4(0x40),
            &Value::Date(2.5),
        )
        .unwrap();
        let r = p.read(&Value::I4(3), &s("KW_A000"), 4.0).unwrap();
        assert_eq!(
            (r.value, r.quality, r.timestamp),
            (Value::R8(1.5), 0x40, 2.5)
        );
        assert_eq!(
            p.write(&s("KW_A000"), &s("text"), 3.0).unwrap_err().code,
            DISP_E_TYPEMISMATCH
        );
        assert_eq!(
            p.write_ex(
                &s("KW_A000"),
                &Value::I4(1),
                &Value::I4(0x1_0000),
                &Value::Date(1.0)
            )
            .unwrap_err()
            .code,
            DISP_E_TYPEMISMATCH
        );
    }

    #[test]
    fn fail_and_hang_switches() {
        let mut p = Plant::new();
        p.init(&s("Fail=Read,WriteEx;Hang=write;HangMs=50"), 1.0)
            .unwrap();
        assert_eq!(
            p.read(&Value::I4(2), &s("KW_A000"), 1.0).unwrap_err().code,
            NET_ANSWER_TIMEOUT
        );
        let e = p
            .write_ex(
                &s("KW_A000"),
                &Value::I4(1),
                &Value::I4(0xC0),
                &Value::Date(1.0),
            )
            .unwrap_err();
        assert_eq!(e.code, WRITE_ERROR);
        assert!(e.text.contains("Fail=WriteEx"), "{}", e.text);
        p.write(&s("KW_A000"), &Value::I4(1), 1.0).unwrap();
        assert_eq!((p.hang_ms("Write"), p.hang_ms("Read")), (Some(50), None));
    }

    #[test]
    fn ticks_change_every_variable_and_report_the_active_ones_while_active() {
        let mut p = Plant::new();
        p.init(&s("Vars=A,B,C"), 1.0).unwrap();
        p.set_item_active(&s("B"), &Value::I4(1)).unwrap();
        assert!(p.tick(2.0).is_empty(), "no events while Active is false");
        p.active = true;
        let events = p.tick(3.0);
        assert_eq!(
            events,
            [Reading {
                item: "B".into(),
                value: Value::R8(21.0),
                quality: GOOD,
                timestamp: 3.0
            }]
        );
        assert_eq!(
            p.read(&Value::I4(2), &s("A"), 4.0).unwrap().value,
            Value::R8(11.0)
        );
        p.set_item_active(&s("B"), &Value::Bool(false)).unwrap();
        assert!(p.tick(4.0).is_empty());
    }
}
