//! Who may write: one policy for every door (DA callers, UA users, asix-link clients),
//! decided here and only here. The front ends say who is calling ([`Caller`]); the engine
//! asks [`WriteRights::decide`] for every item written; the answer names its reason.
//!
//! The policy is the `[WriteRights]` section of `ASIXConnect.ini` (parsed by asix-model's
//! configuration into [`Rule`]s):
//!
//! ```ini
//! [WriteRights]
//! * = group:PLANT\Operators, role:writer      ; every channel
//! Demo_Wytwornia_Kwasu = user:PLANT\jkowalski, cert:3f1a...  ; one channel, in addition
//! ZEZWOLENIE_ZAPISU = KANAL1, KE2.            ; the original's rule: asix client KE2. on KANAL1
//! ```
//!
//! - A channel's writers are the principals listed for it plus those listed for `*`; the
//!   channel is the item's resolved access path as `ASIXConnect.ini` names it
//!   (case-sensitive, `*` for the basic channel, which therefore has only the `*` entries).
//! - Principals ([`Principal::parse`]): `*` or `anyone` (every caller, an unknown one too),
//!   `user:DOMAIN\name` and `group:NAME` (Windows accounts and groups of DA callers;
//!   case-insensitive; a name without `DOMAIN\` matches the name part of any domain),
//!   `ua:user` and `role:name` (UA users and roles; exact), `cert:<SHA-256 fingerprint>`
//!   (an asix-link client's certificate; 64 hex digits, `:` or blanks between them
//!   allowed), `asix:<client name>` (an asix-link client by its asix client name,
//!   case-insensitive; a bare name in a `ZEZWOLENIE_ZAPISU` line means this).
//! - A caller whose identity is unknown ([`Caller::Unknown`]) matches only `*`/`anyone`.
//! - Without a `[WriteRights]` section (and without `ZEZWOLENIE_ZAPISU`) the policy is
//!   [`WriteRights::open`]: every caller may write ([`Reason::NoPolicy`]), which
//!   `opcdiag doctor` reports ([`WriteRights::is_open`]). A section without entries denies
//!   every write.

use std::fmt;

/// A SHA-256 certificate fingerprint.
pub type Fingerprint = [u8; 32];

/// Who an entry of the policy names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Principal {
    /// `*` / `anyone`: every caller, one of unknown identity too.
    Anyone,
    /// `user:DOMAIN\name`: a Windows account.
    WindowsUser(String),
    /// `group:NAME`: a Windows group the caller's token holds.
    WindowsGroup(String),
    /// `ua:user`: an OPC UA user.
    UaUser(String),
    /// `role:name`: an OPC UA role.
    UaRole(String),
    /// `cert:<fingerprint>`: an asix-link client's certificate.
    Certificate(Fingerprint),
    /// `asix:<name>`: an asix-link client by its asix client name (`ZEZWOLENIE_ZAPISU`).
    AsixClient(String),
}

/// Why a principal's text could not be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PrincipalError {
    #[error("empty identity")]
    Empty,
    #[error(
        "`{0}` is not an identity: expected *, anyone, user:DOMAIN\\name, group:NAME, ua:user, role:name, cert:<SHA-256 fingerprint> or asix:<client>"
    )]
    UnknownKind(String),
    #[error("`{0}` names nobody after its prefix")]
    NoName(String),
    #[error("`{0}`: a certificate fingerprint is 64 hexadecimal digits (SHA-256), `:` or blanks between them allowed")]
    BadFingerprint(String),
}

impl Principal {
    /// Reads one identity as the policy spells it (see the module doc).
    pub fn parse(text: &str) -> Result<Principal, PrincipalError> {
        let text = text.trim();
        if text.is_empty() {
            return Err(PrincipalError::Empty);
        }
        if text == "*" || text.eq_ignore_ascii_case("anyone") {
            return Ok(Principal::Anyone);
        }
        let Some((kind, name)) = text.split_once(':') else {
            return Err(PrincipalError::UnknownKind(text.to_owned()));
        };
        let name = name.trim();
        if name.is_empty() {
            return Err(PrincipalError::NoName(text.to_owned()));
        }
        let kind = kind.trim().to_ascii_lowercase();
        Ok(match kind.as_str() {
            "user" => Principal::WindowsUser(name.to_owned()),
            "group" => Principal::WindowsGroup(name.to_owned()),
            "ua" => Principal::UaUser(name.to_owned()),
            "role" => Principal::UaRole(name.to_owned()),
            "cert" => Principal::Certificate(
                parse_fingerprint(name)
                    .ok_or_else(|| PrincipalError::BadFingerprint(text.to_owned()))?,
            ),
            "asix" => Principal::AsixClient(name.to_owned()),
            _ => return Err(PrincipalError::UnknownKind(text.to_owned())),
        })
    }

    /// Reads a client of a `ZEZWOLENIE_ZAPISU` line: a bare name is an asix client name
    /// (the original's meaning), anything else as [`Principal::parse`].
    pub fn parse_asix_permit(text: &str) -> Result<Principal, PrincipalError> {
        let t = text.trim();
        if t.is_empty() {
            return Err(PrincipalError::Empty);
        }
        if t == "*" || t.eq_ignore_ascii_case("anyone") || t.contains(':') {
            return Principal::parse(t);
        }
        Ok(Principal::AsixClient(t.to_owned()))
    }

    fn matches(&self, caller: &Caller) -> bool {
        match (self, caller) {
            (Principal::Anyone, _) => true,
            (Principal::WindowsUser(u), Caller::Windows { account, .. }) => {
                account_matches(u, account)
            }
            (Principal::WindowsGroup(g), Caller::Windows { groups, .. }) => {
                groups.iter().any(|have| account_matches(g, have))
            }
            (Principal::UaUser(u), Caller::Ua { user, .. }) => u == user,
            (Principal::UaRole(r), Caller::Ua { roles, .. }) => roles.iter().any(|x| x == r),
            (
                Principal::Certificate(f),
                Caller::Link {
                    certificate: Some(c),
                    ..
                },
            ) => f == c,
            (
                Principal::AsixClient(n),
                Caller::Link {
                    client: Some(c), ..
                },
            ) => n.eq_ignore_ascii_case(c),
            _ => false,
        }
    }
}

/// A Windows name in the policy against the caller's: a qualified name (`DOMAIN\name`)
/// compares whole, an unqualified one with the name part; ASCII case-insensitive (as
/// Windows compares account names).
fn account_matches(want: &str, have: &str) -> bool {
    if want.contains('\\') {
        return want.eq_ignore_ascii_case(have);
    }
    let name = have.rsplit_once('\\').map_or(have, |(_, n)| n);
    want.eq_ignore_ascii_case(name)
}

/// 64 hex digits, optionally separated by `:` or blanks.
fn parse_fingerprint(text: &str) -> Option<Fingerprint> {
    let digits: Vec<u8> = text
        .bytes()
        .filter(|b| !matches!(b, b':' | b' ' | b'\t'))
        .collect();
    if digits.len() != 64 {
        return None;
    }
    let mut out = [0u8; 32];
    for (i, pair) in digits.chunks(2).enumerate() {
        let hi = (pair[0] as char).to_digit(16)?;
        let lo = (pair[1] as char).to_digit(16)?;
        out[i] = (hi * 16 + lo) as u8;
    }
    Some(out)
}

fn hex(f: &Fingerprint) -> String {
    f.iter().map(|b| format!("{b:02x}")).collect()
}

impl fmt::Display for Principal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Principal::Anyone => f.write_str("*"),
            Principal::WindowsUser(u) => write!(f, "user:{u}"),
            Principal::WindowsGroup(g) => write!(f, "group:{g}"),
            Principal::UaUser(u) => write!(f, "ua:{u}"),
            Principal::UaRole(r) => write!(f, "role:{r}"),
            Principal::Certificate(c) => write!(f, "cert:{}", hex(c)),
            Principal::AsixClient(n) => write!(f, "asix:{n}"),
        }
    }
}

/// Who is calling, as the front end that received the call can tell.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Caller {
    /// A DA caller's Windows account (`DOMAIN\name`) and the groups of its token
    /// (`DOMAIN\name` each, `BUILTIN\Administrators`, ...).
    Windows {
        account: String,
        groups: Vec<String>,
    },
    /// An OPC UA session's user and roles.
    Ua { user: String, roles: Vec<String> },
    /// An asix-link client: its asix client name and its certificate, as far as known.
    Link {
        client: Option<String>,
        certificate: Option<Fingerprint>,
    },
    /// The platform could not tell (an unauthenticated caller, a platform without the
    /// security context); says why.
    Unknown { reason: String },
}

impl Caller {
    /// A caller of unknown identity, with the reason.
    pub fn unknown(reason: impl Into<String>) -> Caller {
        Caller::Unknown {
            reason: reason.into(),
        }
    }

    pub fn is_unknown(&self) -> bool {
        matches!(self, Caller::Unknown { .. })
    }
}

impl Default for Caller {
    fn default() -> Self {
        Caller::unknown("not told")
    }
}

/// The identity as logs and `_Diagnostics` show it, in the policy's spelling where there
/// is one (`user:PLANT\op`, `ua:op`, `cert:…`, `asix:KE2.`), else `unknown (<reason>)`.
impl fmt::Display for Caller {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Caller::Windows { account, .. } => write!(f, "user:{account}"),
            Caller::Ua { user, .. } => write!(f, "ua:{user}"),
            Caller::Link {
                certificate: Some(c),
                ..
            } => write!(f, "cert:{}", hex(c)),
            Caller::Link {
                client: Some(n), ..
            } => write!(f, "asix:{n}"),
            Caller::Link { .. } => f.write_str("unknown (asix-link client without a name)"),
            Caller::Unknown { reason } => write!(f, "unknown ({reason})"),
        }
    }
}

/// Which channels an entry is for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Channels {
    /// `*`: every channel.
    All,
    /// One channel, by its `ASIXConnect.ini` name (case-sensitive).
    One(String),
}

impl fmt::Display for Channels {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Channels::All => f.write_str("*"),
            Channels::One(c) => f.write_str(c),
        }
    }
}

/// One entry: `channels` may be written by `principal`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rule {
    pub channels: Channels,
    pub principal: Principal,
}

impl Rule {
    pub fn new(channels: Channels, principal: Principal) -> Rule {
        Rule {
            channels,
            principal,
        }
    }
}

/// The policy (see the module doc).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriteRights {
    /// `None`: no policy configured, every caller may write.
    rules: Option<Vec<Rule>>,
}

impl Default for WriteRights {
    fn default() -> Self {
        WriteRights::open()
    }
}

/// Why a write was allowed or denied.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reason {
    /// No policy is configured: every caller may write.
    NoPolicy,
    /// This entry names the caller.
    Granted(Rule),
    /// The caller is known and no entry for the channel names it.
    NotListed,
    /// The caller's identity is unknown and no entry for the channel says `*`.
    UnknownCaller,
}

/// The answer for one write.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Decision {
    pub allowed: bool,
    pub reason: Reason,
}

impl fmt::Display for Decision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.reason {
            Reason::NoPolicy => {
                f.write_str("allowed: no [WriteRights] policy, every client may write")
            }
            Reason::Granted(r) => {
                write!(
                    f,
                    "allowed by [WriteRights] {} = {}",
                    r.channels, r.principal
                )
            }
            Reason::NotListed => f.write_str("denied: no [WriteRights] entry names the caller"),
            Reason::UnknownCaller => f.write_str(
                "denied: the caller's identity is unknown and no [WriteRights] entry says *",
            ),
        }
    }
}

impl WriteRights {
    /// No policy: every caller may write.
    pub fn open() -> WriteRights {
        WriteRights { rules: None }
    }

    /// A configured policy (an empty list denies every write).
    pub fn new(rules: Vec<Rule>) -> WriteRights {
        WriteRights { rules: Some(rules) }
    }

    /// True when no policy is configured (every connected client may write).
    pub fn is_open(&self) -> bool {
        self.rules.is_none()
    }

    /// The entries, in file order (none for an open policy).
    pub fn rules(&self) -> &[Rule] {
        self.rules.as_deref().unwrap_or(&[])
    }

    /// May `caller` write an item of `channel` (the item's resolved access path)?
    pub fn decide(&self, channel: &str, caller: &Caller) -> Decision {
        let Some(rules) = &self.rules else {
            return Decision {
                allowed: true,
                reason: Reason::NoPolicy,
            };
        };
        let granted = rules.iter().find(|r| {
            let for_channel = match &r.channels {
                Channels::All => true,
                Channels::One(c) => c == channel,
            };
            for_channel && r.principal.matches(caller)
        });
        match granted {
            Some(r) => Decision {
                allowed: true,
                reason: Reason::Granted(r.clone()),
            },
            None => Decision {
                allowed: false,
                reason: if caller.is_unknown() {
                    Reason::UnknownCaller
                } else {
                    Reason::NotListed
                },
            },
        }
    }

    /// Shorthand for `decide(..).allowed`.
    pub fn allows(&self, channel: &str, caller: &Caller) -> bool {
        self.decide(channel, caller).allowed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FP: &str = "3f1a00112233445566778899aabbccddeeff00112233445566778899aabbccdd";

    fn fp() -> Fingerprint {
        parse_fingerprint(FP).unwrap()
    }

    fn win(account: &str, groups: &[&str]) -> Caller {
        Caller::Windows {
            account: account.into(),
            groups: groups.iter().map(|g| (*g).to_owned()).collect(),
        }
    }

    fn ua(user: &str, roles: &[&str]) -> Caller {
        Caller::Ua {
            user: user.into(),
            roles: roles.iter().map(|g| (*g).to_owned()).collect(),
        }
    }

    fn link(client: Option<&str>, certificate: Option<Fingerprint>) -> Caller {
        Caller::Link {
            client: client.map(str::to_owned),
            certificate,
        }
    }

    fn rule(channel: &str, principal: &str) -> Rule {
        let channels = if channel == "*" {
            Channels::All
        } else {
            Channels::One(channel.into())
        };
        Rule::new(channels, Principal::parse(principal).unwrap())
    }

    fn policy() -> WriteRights {
        WriteRights::new(vec![
            rule("*", "group:PLANT\\Operators"),
            rule("*", "role:writer"),
            rule("KWAS", "user:PLANT\\jkowalski"),
            rule("KWAS", "group:Engineers"),
            rule("KWAS", "ua:hmi"),
            rule("KWAS", &format!("cert:{FP}")),
            rule("KWAS", "asix:KE2."),
            rule("OPEN", "anyone"),
        ])
    }

    /// The decision table: channel, caller, allowed, reason.
    #[test]
    fn the_decision_table() {
        let p = policy();
        let granted = |c: &str, pr: &str| Reason::Granted(rule(c, pr));
        let rows: Vec<(&str, Caller, bool, Reason)> = vec![
            // a group on every channel; groups compare case-insensitively
            (
                "KWAS",
                win("PLANT\\x", &["plant\\operators"]),
                true,
                granted("*", "group:PLANT\\Operators"),
            ),
            (
                "*",
                win("PLANT\\x", &["PLANT\\Operators"]),
                true,
                granted("*", "group:PLANT\\Operators"),
            ),
            // a qualified group does not match the same name in another domain
            (
                "KWAS",
                win("EVIL\\x", &["EVIL\\Operators"]),
                false,
                Reason::NotListed,
            ),
            // an unqualified group matches the name part of any domain
            (
                "KWAS",
                win("X\\y", &["BUILTIN\\engineers"]),
                true,
                granted("KWAS", "group:Engineers"),
            ),
            (
                "OTHER",
                win("X\\y", &["BUILTIN\\Engineers"]),
                false,
                Reason::NotListed,
            ),
            // a user on one channel only, case-insensitive
            (
                "KWAS",
                win("plant\\JKOWALSKI", &[]),
                true,
                granted("KWAS", "user:PLANT\\jkowalski"),
            ),
            (
                "OTHER",
                win("PLANT\\jkowalski", &[]),
                false,
                Reason::NotListed,
            ),
            // channel names are case-sensitive
            (
                "kwas",
                win("PLANT\\jkowalski", &[]),
                false,
                Reason::NotListed,
            ),
            // UA users exactly, roles on every channel
            ("KWAS", ua("hmi", &[]), true, granted("KWAS", "ua:hmi")),
            ("KWAS", ua("HMI", &[]), false, Reason::NotListed),
            (
                "OTHER",
                ua("anyone-at-all", &["writer"]),
                true,
                granted("*", "role:writer"),
            ),
            ("OTHER", ua("hmi", &["reader"]), false, Reason::NotListed),
            // a UA user never matches a Windows entry of the same spelling
            (
                "KWAS",
                ua("PLANT\\jkowalski", &["PLANT\\Operators"]),
                false,
                Reason::NotListed,
            ),
            // asix-link clients by certificate or by asix client name
            (
                "KWAS",
                link(None, Some(fp())),
                true,
                granted("KWAS", &format!("cert:{FP}")),
            ),
            (
                "KWAS",
                link(Some("ke2."), None),
                true,
                granted("KWAS", "asix:KE2."),
            ),
            ("KWAS", link(Some("KE2"), None), false, Reason::NotListed),
            (
                "OTHER",
                link(Some("KE2."), Some(fp())),
                false,
                Reason::NotListed,
            ),
            // unknown callers: only `anyone`
            (
                "KWAS",
                Caller::unknown("Wine"),
                false,
                Reason::UnknownCaller,
            ),
            (
                "OPEN",
                Caller::unknown("Wine"),
                true,
                granted("OPEN", "anyone"),
            ),
            ("OPEN", win("A\\b", &[]), true, granted("OPEN", "anyone")),
        ];
        for (channel, caller, allowed, reason) in rows {
            let d = p.decide(channel, &caller);
            assert_eq!(
                (d.allowed, &d.reason),
                (allowed, &reason),
                "channel {channel}, caller {caller}"
            );
            assert_eq!(p.allows(channel, &caller), allowed);
        }
    }

    #[test]
    fn no_policy_lets_everyone_write_and_says_so() {
        let p = WriteRights::open();
        assert!(p.is_open());
        assert!(p.rules().is_empty());
        for caller in [Caller::unknown("x"), win("A\\b", &[]), ua("u", &[])] {
            let d = p.decide("KWAS", &caller);
            assert!(d.allowed);
            assert_eq!(d.reason, Reason::NoPolicy);
            assert!(d.to_string().contains("every client may write"), "{d}");
        }
        assert_eq!(WriteRights::default(), WriteRights::open());
    }

    #[test]
    fn an_empty_policy_denies_everyone() {
        let p = WriteRights::new(Vec::new());
        assert!(!p.is_open());
        assert!(!p.allows("KWAS", &win("A\\b", &["BUILTIN\\Administrators"])));
        assert_eq!(
            p.decide("*", &Caller::unknown("x")).reason,
            Reason::UnknownCaller
        );
    }

    #[test]
    fn principals_parse_and_print_in_the_policy_spelling() {
        let ok = [
            ("*", "*"),
            ("Anyone", "*"),
            ("user:PLANT\\op", "user:PLANT\\op"),
            ("USER : PLANT\\op ", "user:PLANT\\op"),
            ("group:Administrators", "group:Administrators"),
            ("ua:hmi", "ua:hmi"),
            ("role:writer", "role:writer"),
            ("asix:KE2.", "asix:KE2."),
        ];
        for (text, shown) in ok {
            assert_eq!(Principal::parse(text).unwrap().to_string(), shown, "{text}");
        }
        let colons: String = FP
            .as_bytes()
            .chunks(2)
            .map(|c| std::str::from_utf8(c).unwrap().to_ascii_uppercase())
            .collect::<Vec<_>>()
            .join(":");
        assert_eq!(
            Principal::parse(&format!("cert:{colons}")).unwrap(),
            Principal::Certificate(fp())
        );
        assert_eq!(
            Principal::parse(&format!("cert:{FP}")).unwrap().to_string(),
            format!("cert:{FP}")
        );
    }

    #[test]
    fn bad_principals_say_what_is_expected() {
        assert_eq!(Principal::parse("  "), Err(PrincipalError::Empty));
        assert!(matches!(
            Principal::parse("jkowalski"),
            Err(PrincipalError::UnknownKind(_))
        ));
        assert!(matches!(
            Principal::parse("machine:X"),
            Err(PrincipalError::UnknownKind(_))
        ));
        assert!(matches!(
            Principal::parse("user:"),
            Err(PrincipalError::NoName(_))
        ));
        for bad in [
            "cert:abc",
            &format!("cert:{FP}00"),
            &format!("cert:{}", "g".repeat(64)),
        ] {
            let e = Principal::parse(bad).unwrap_err();
            assert!(matches!(e, PrincipalError::BadFingerprint(_)), "{bad}");
            assert!(e.to_string().contains("64 hexadecimal digits"));
        }
        let e = Principal::parse("jkowalski").unwrap_err().to_string();
        assert!(
            e.contains("user:DOMAIN\\name") && e.contains("cert:"),
            "{e}"
        );
    }

    #[test]
    fn asix_permits_read_bare_names_as_asix_clients() {
        assert_eq!(
            Principal::parse_asix_permit(" KE2. ").unwrap(),
            Principal::AsixClient("KE2.".into())
        );
        assert_eq!(
            Principal::parse_asix_permit("user:PLANT\\op").unwrap(),
            Principal::WindowsUser("PLANT\\op".into())
        );
        assert_eq!(
            Principal::parse_asix_permit("*").unwrap(),
            Principal::Anyone
        );
        assert_eq!(Principal::parse_asix_permit(""), Err(PrincipalError::Empty));
    }

    #[test]
    fn callers_show_their_identity() {
        assert_eq!(win("PLANT\\op", &["x"]).to_string(), "user:PLANT\\op");
        assert_eq!(ua("hmi", &[]).to_string(), "ua:hmi");
        assert_eq!(link(Some("KE2."), None).to_string(), "asix:KE2.");
        assert_eq!(
            link(Some("KE2."), Some(fp())).to_string(),
            format!("cert:{FP}")
        );
        assert_eq!(
            Caller::unknown("RPC_E_CALL_COMPLETE").to_string(),
            "unknown (RPC_E_CALL_COMPLETE)"
        );
        assert_eq!(Caller::default().to_string(), "unknown (not told)");
        assert!(link(None, None).to_string().starts_with("unknown ("));
    }

    #[test]
    fn decisions_explain_themselves() {
        let p = policy();
        let d = p.decide("KWAS", &win("PLANT\\jkowalski", &[]));
        assert_eq!(
            d.to_string(),
            "allowed by [WriteRights] KWAS = user:PLANT\\jkowalski"
        );
        let d = p.decide("KWAS", &Caller::unknown("x"));
        assert!(d
            .to_string()
            .starts_with("denied: the caller's identity is unknown"));
        let d = p.decide("KWAS", &win("A\\b", &[]));
        assert!(d.to_string().starts_with("denied: no [WriteRights] entry"));
    }
}
