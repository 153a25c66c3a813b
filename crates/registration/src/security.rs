//! The AppID's security, the Windows way, as data: the self-relative security descriptors
//! of `AccessPermission` and `LaunchPermission` and the `AuthenticationLevel` that
//! `/RegServer`, `/Service` and the MSI write **where absent** (an administrator's changes
//! through dcomcnfg stay), and their reading back for `opcdiag doctor`.
//!
//! Binary layouts from MS-DTYP: SID 2.4.2.2, ACE header 2.4.4.1, ACCESS_ALLOWED_ACE
//! 2.4.4.2, ACL 2.4.5, SECURITY_DESCRIPTOR (self-relative) 2.4.6. The descriptors are
//! `O:BAG:BA` (owner and group Administrators, which COM requires) with a DACL of allow
//! ACEs:
//!
//! | who | access | launch |
//! |---|---|---|
//! | Administrators `S-1-5-32-544`, SYSTEM `S-1-5-18`, INTERACTIVE `S-1-5-4` | local (`0x3`) | local launch and activation (`0xB`) |
//! | LocalService `S-1-5-19` (when installed as a service: the service's account) | local | local |
//! | the local group `ServerCTOPC Clients` (when it exists) | local and remote (`0x7`) | local and remote (`0x1F`) |
//!
//! so remote clients get in only through that group. `AuthenticationLevel` = 5
//! (`RPC_C_AUTHN_LEVEL_PKT_INTEGRITY`, what the KB5004442 hardening expects).

/// A SID in its binary form (MS-DTYP 2.4.2.2).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Sid(Vec<u8>);

/// `S-1-5-32-544`: BUILTIN\Administrators.
pub const ADMINISTRATORS: &str = "S-1-5-32-544";
/// `S-1-5-18`: NT AUTHORITY\SYSTEM.
pub const SYSTEM: &str = "S-1-5-18";
/// `S-1-5-4`: NT AUTHORITY\INTERACTIVE (users logged on at the machine).
pub const INTERACTIVE: &str = "S-1-5-4";
/// `S-1-5-19`: NT AUTHORITY\LOCAL SERVICE (the account the service runs as).
pub const LOCAL_SERVICE: &str = "S-1-5-19";
/// `S-1-1-0`: Everyone.
pub const EVERYONE: &str = "S-1-1-0";
/// `S-1-5-7`: ANONYMOUS LOGON.
pub const ANONYMOUS: &str = "S-1-5-7";
/// `S-1-5-11`: Authenticated Users.
pub const AUTHENTICATED_USERS: &str = "S-1-5-11";
/// `S-1-5-2`: NETWORK (users logged on over the network).
pub const NETWORK: &str = "S-1-5-2";

/// The local group whose members may use the server, also remotely (created by the MSI;
/// `/RegServer` grants it when it exists).
pub const CLIENTS_GROUP: &str = "ServerCTOPC Clients";

/// COM rights (`COM_RIGHTS_*`) in an AppID's ACEs.
pub const COM_RIGHTS_EXECUTE: u32 = 0x1;
pub const COM_RIGHTS_EXECUTE_LOCAL: u32 = 0x2;
pub const COM_RIGHTS_EXECUTE_REMOTE: u32 = 0x4;
pub const COM_RIGHTS_ACTIVATE_LOCAL: u32 = 0x8;
pub const COM_RIGHTS_ACTIVATE_REMOTE: u32 = 0x10;

/// Local access (`AccessPermission`).
pub const ACCESS_LOCAL: u32 = COM_RIGHTS_EXECUTE | COM_RIGHTS_EXECUTE_LOCAL;
/// Local and remote access.
pub const ACCESS_REMOTE: u32 = ACCESS_LOCAL | COM_RIGHTS_EXECUTE_REMOTE;
/// Local launch and activation (`LaunchPermission`).
pub const LAUNCH_LOCAL: u32 = ACCESS_LOCAL | COM_RIGHTS_ACTIVATE_LOCAL;
/// Local and remote launch and activation.
pub const LAUNCH_REMOTE: u32 =
    LAUNCH_LOCAL | COM_RIGHTS_EXECUTE_REMOTE | COM_RIGHTS_ACTIVATE_REMOTE;

/// `RPC_C_AUTHN_LEVEL_PKT_INTEGRITY`.
pub const AUTHN_LEVEL_PKT_INTEGRITY: u32 = 5;

/// The AppID value names.
pub const ACCESS_PERMISSION: &str = "AccessPermission";
pub const LAUNCH_PERMISSION: &str = "LaunchPermission";
pub const AUTHENTICATION_LEVEL: &str = "AuthenticationLevel";

const SE_DACL_PRESENT: u16 = 0x0004;
const SE_DACL_PROTECTED: u16 = 0x1000;
const SE_SELF_RELATIVE: u16 = 0x8000;
const ACL_REVISION: u8 = 2;
const ACCESS_ALLOWED_ACE_TYPE: u8 = 0;
const ACCESS_DENIED_ACE_TYPE: u8 = 1;

impl Sid {
    /// Parses `S-1-<authority>-<sub>...` (at most 15 sub-authorities, MS-DTYP 2.4.2.1).
    pub fn parse(text: &str) -> Option<Sid> {
        let mut parts = text.strip_prefix("S-")?.split('-');
        let revision: u8 = parts.next()?.parse().ok()?;
        let authority: u64 = parts.next()?.parse().ok()?;
        if revision != 1 || authority >= 1 << 48 {
            return None;
        }
        let subs: Vec<u32> = parts.map(|p| p.parse().ok()).collect::<Option<_>>()?;
        if subs.len() > 15 {
            return None;
        }
        let mut b = vec![revision, subs.len() as u8];
        b.extend_from_slice(&authority.to_be_bytes()[2..]);
        for s in subs {
            b.extend_from_slice(&s.to_le_bytes());
        }
        Some(Sid(b))
    }

    /// A SID from its binary form (checked: revision 1, the length its count says).
    pub fn from_bytes(b: &[u8]) -> Option<Sid> {
        let n = usize::from(*b.get(1)?);
        (b.first() == Some(&1) && n <= 15 && b.len() == 8 + 4 * n).then(|| Sid(b.to_vec()))
    }

    /// A well-known SID constant of this module (panics on a bad literal: programmer error).
    fn known(text: &str) -> Sid {
        match Sid::parse(text) {
            Some(s) => s,
            None => panic!("bad SID literal {text}"),
        }
    }

    pub fn as_bytes(&self) -> &[u8] {
        &self.0
    }
}

impl std::fmt::Display for Sid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let authority = self.0[2..8]
            .iter()
            .fold(0u64, |a, b| (a << 8) | u64::from(*b));
        write!(f, "S-{}-{authority}", self.0[0])?;
        for s in self.0[8..].chunks_exact(4) {
            write!(f, "-{}", u32::from_le_bytes([s[0], s[1], s[2], s[3]]))?;
        }
        Ok(())
    }
}

/// One ACE of a DACL.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ace {
    pub allow: bool,
    /// The ACE flags (`OBJECT_INHERIT_ACE`, `CONTAINER_INHERIT_ACE`, `INHERITED_ACE`, ...).
    pub flags: u8,
    pub mask: u32,
    pub sid: Sid,
}

impl Ace {
    pub fn allow(sid: Sid, mask: u32) -> Ace {
        Ace {
            allow: true,
            flags: 0,
            mask,
            sid,
        }
    }

    /// Was the ACE inherited from the parent (`INHERITED_ACE`)?
    pub fn inherited(&self) -> bool {
        self.flags & INHERITED_ACE != 0
    }
}

/// A self-relative security descriptor with owner, group and DACL (no SACL).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Descriptor {
    pub owner: Option<Sid>,
    pub group: Option<Sid>,
    /// `None`: no DACL (a NULL DACL: everyone may).
    pub dacl: Option<Vec<Ace>>,
    /// `SE_DACL_PROTECTED`: the DACL takes nothing from the parent's inheritable ACEs.
    pub protected: bool,
}

impl Descriptor {
    /// The binary self-relative form: the 20-byte header, then the DACL, the owner, the
    /// group (the order Windows writes them in).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut body = Vec::new();
        let offset = |part: &[u8], body: &mut Vec<u8>| -> u32 {
            let at = 20 + body.len() as u32;
            body.extend_from_slice(part);
            at
        };
        let dacl = self.dacl.as_ref().map(|aces| acl_bytes(aces));
        let dacl_at = dacl.as_ref().map_or(0, |d| offset(d, &mut body));
        let owner_at = self.owner.as_ref().map_or(0, |s| offset(&s.0, &mut body));
        let group_at = self.group.as_ref().map_or(0, |s| offset(&s.0, &mut body));
        let mut control = SE_SELF_RELATIVE;
        if self.dacl.is_some() {
            control |= SE_DACL_PRESENT;
        }
        if self.protected {
            control |= SE_DACL_PROTECTED;
        }
        let mut out = vec![1, 0];
        out.extend_from_slice(&control.to_le_bytes());
        for at in [owner_at, group_at, 0, dacl_at] {
            out.extend_from_slice(&at.to_le_bytes());
        }
        out.extend_from_slice(&body);
        out
    }

    /// Reads a self-relative descriptor (what the registry holds); `None` when it is not
    /// one. Only allow and deny ACEs are kept; other ACE types are skipped.
    pub fn from_bytes(b: &[u8]) -> Option<Descriptor> {
        if b.len() < 20 || b[0] != 1 {
            return None;
        }
        let control = u16::from_le_bytes([b[2], b[3]]);
        if control & SE_SELF_RELATIVE == 0 {
            return None;
        }
        let u32_at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]) as usize;
        let sid_at = |at: usize| -> Option<Option<Sid>> {
            if at == 0 {
                return Some(None);
            }
            let n = usize::from(*b.get(at + 1)?);
            Sid::from_bytes(b.get(at..at + 8 + 4 * n)?).map(Some)
        };
        let owner = sid_at(u32_at(4))?;
        let group = sid_at(u32_at(8))?;
        let dacl_at = u32_at(16);
        let dacl = if control & SE_DACL_PRESENT == 0 || dacl_at == 0 {
            None
        } else {
            Some(parse_acl(b.get(dacl_at..)?)?)
        };
        Some(Descriptor {
            owner,
            group,
            dacl,
            protected: control & SE_DACL_PROTECTED != 0,
        })
    }

    /// The descriptor in SDDL (`O:..G:..D:(A;;0x3;;;S-1-5-18)...`, SIDs and masks as
    /// numbers), for messages.
    pub fn sddl(&self) -> String {
        let mut s = String::new();
        if let Some(o) = &self.owner {
            s.push_str(&format!("O:{o}"));
        }
        if let Some(g) = &self.group {
            s.push_str(&format!("G:{g}"));
        }
        match &self.dacl {
            None => s.push_str("D:NO_ACCESS_CONTROL"),
            Some(aces) => {
                s.push_str("D:");
                for a in aces {
                    let t = if a.allow { "A" } else { "D" };
                    s.push_str(&format!("({t};;{:#x};;;{})", a.mask, a.sid));
                }
            }
        }
        s
    }
}

fn acl_bytes(aces: &[Ace]) -> Vec<u8> {
    let mut body = Vec::new();
    for a in aces {
        let size = (8 + a.sid.0.len()) as u16;
        body.push(if a.allow {
            ACCESS_ALLOWED_ACE_TYPE
        } else {
            ACCESS_DENIED_ACE_TYPE
        });
        body.push(a.flags);
        body.extend_from_slice(&size.to_le_bytes());
        body.extend_from_slice(&a.mask.to_le_bytes());
        body.extend_from_slice(&a.sid.0);
    }
    let mut out = vec![ACL_REVISION, 0];
    out.extend_from_slice(&((8 + body.len()) as u16).to_le_bytes());
    out.extend_from_slice(&(aces.len() as u16).to_le_bytes());
    out.extend_from_slice(&[0, 0]);
    out.extend_from_slice(&body);
    out
}

fn parse_acl(b: &[u8]) -> Option<Vec<Ace>> {
    if b.len() < 8 {
        return None;
    }
    let size = usize::from(u16::from_le_bytes([b[2], b[3]]));
    let count = usize::from(u16::from_le_bytes([b[4], b[5]]));
    let acl = b.get(..size)?;
    let mut at = 8;
    let mut aces = Vec::new();
    for _ in 0..count {
        let header = acl.get(at..at + 4)?;
        let ace_size = usize::from(u16::from_le_bytes([header[2], header[3]]));
        let ace = acl.get(at..at + ace_size)?;
        if ace_size < 8 {
            return None;
        }
        if matches!(header[0], ACCESS_ALLOWED_ACE_TYPE | ACCESS_DENIED_ACE_TYPE) {
            aces.push(Ace {
                allow: header[0] == ACCESS_ALLOWED_ACE_TYPE,
                flags: header[1],
                mask: u32::from_le_bytes([ace[4], ace[5], ace[6], ace[7]]),
                sid: Sid::from_bytes(&ace[8..])?,
            });
        }
        at += ace_size;
    }
    Some(aces)
}

/// Who the defaults grant: the fixed accounts, the service's account when installed as a
/// service, and the clients' group when its SID is known.
fn granted(service: bool, clients: Option<&Sid>, local: u32, remote: u32) -> Descriptor {
    let admins = Sid::known(ADMINISTRATORS);
    let mut aces = vec![
        Ace::allow(admins.clone(), local),
        Ace::allow(Sid::known(SYSTEM), local),
        Ace::allow(Sid::known(INTERACTIVE), local),
    ];
    if service {
        aces.push(Ace::allow(Sid::known(LOCAL_SERVICE), local));
    }
    if let Some(c) = clients {
        aces.push(Ace::allow(c.clone(), remote));
    }
    Descriptor {
        owner: Some(admins.clone()),
        group: Some(admins),
        dacl: Some(aces),
        protected: false,
    }
}

/// The default `AccessPermission` (see the module doc).
pub fn default_access(service: bool, clients: Option<&Sid>) -> Descriptor {
    granted(service, clients, ACCESS_LOCAL, ACCESS_REMOTE)
}

/// The default `LaunchPermission` (see the module doc).
pub fn default_launch(service: bool, clients: Option<&Sid>) -> Descriptor {
    granted(service, clients, LAUNCH_LOCAL, LAUNCH_REMOTE)
}

/// A registry value's data.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Data {
    /// `REG_BINARY`.
    Binary(Vec<u8>),
    /// `REG_DWORD`.
    Dword(u32),
}

/// A value written only where the key does not have it yet.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DefaultValue {
    pub view: crate::View,
    /// Below `HKEY_CLASSES_ROOT`.
    pub path: String,
    pub name: &'static str,
    pub data: Data,
}

/// The AppID security values of `appid`, both views, to write where absent.
pub fn appid_defaults(appid: u128, service: bool, clients: Option<&Sid>) -> Vec<DefaultValue> {
    let path = format!("AppID\\{}", crate::guid_string(appid));
    crate::VIEWS
        .iter()
        .flat_map(|&view| {
            [
                (
                    ACCESS_PERMISSION,
                    Data::Binary(default_access(service, clients).to_bytes()),
                ),
                (
                    LAUNCH_PERMISSION,
                    Data::Binary(default_launch(service, clients).to_bytes()),
                ),
                (AUTHENTICATION_LEVEL, Data::Dword(AUTHN_LEVEL_PKT_INTEGRITY)),
            ]
            .map(|(name, data)| DefaultValue {
                view,
                path: path.clone(),
                name,
                data,
            })
        })
        .collect()
}

/// What is weaker in an AppID's descriptor than the defaults: no DACL, or an allow ACE
/// that gives Everyone, Anonymous, Authenticated Users or NETWORK anything, or remote
/// rights to anyone but the clients' group (`clients`, when known). One sentence each.
pub fn weaker_than_default(d: &Descriptor, clients: Option<&Sid>) -> Vec<String> {
    let Some(aces) = &d.dacl else {
        return vec!["no DACL: every caller is allowed".into()];
    };
    let broad = [
        (EVERYONE, "Everyone"),
        (ANONYMOUS, "ANONYMOUS LOGON"),
        (AUTHENTICATED_USERS, "Authenticated Users"),
        (NETWORK, "NETWORK"),
    ];
    let mut out = Vec::new();
    for a in aces.iter().filter(|a| a.allow && a.mask != 0) {
        if let Some((_, name)) = broad.iter().find(|(s, _)| Sid::known(s) == a.sid) {
            out.push(format!("{name} ({}) is allowed {:#x}", a.sid, a.mask));
        } else if a.mask & (COM_RIGHTS_EXECUTE_REMOTE | COM_RIGHTS_ACTIVATE_REMOTE) != 0
            && Some(&a.sid) != clients
        {
            out.push(format!("{} has remote rights ({:#x})", a.sid, a.mask));
        }
    }
    out
}

/// Is an `AuthenticationLevel` weaker than the default (packet integrity)? `None` (absent:
/// the machine-wide default applies, usually connect) counts as weaker.
pub fn authentication_level_weaker(level: Option<u32>) -> bool {
    level.is_none_or(|l| l < AUTHN_LEVEL_PKT_INTEGRITY)
}

/// `S-1-5-32-545`: BUILTIN\Users.
pub const USERS: &str = "S-1-5-32-545";

/// ACE flags: inherited by files, by folders, and inherited from the parent.
pub const OBJECT_INHERIT_ACE: u8 = 0x01;
pub const CONTAINER_INHERIT_ACE: u8 = 0x02;
pub const INHERITED_ACE: u8 = 0x10;

/// `FILE_ALL_ACCESS`: full control of a file or folder.
pub const FILE_ALL_ACCESS: u32 = 0x001F_01FF;

/// Who always may hold rights on a file of secrets (a private key, the OPC UA users file)
/// or its folder: SYSTEM, Administrators and LOCAL SERVICE (the account of the service the
/// MSI installs), besides the account that writes the file (its owner).
pub const SECRET_HOLDERS: [&str; 3] = [SYSTEM, ADMINISTRATORS, LOCAL_SERVICE];

/// The descriptor a file of secrets is written with (`folder`: its folder): a protected
/// DACL (nothing inherited from the parent) giving full control to [`SECRET_HOLDERS`] and
/// `writer`, the account that writes it; a folder's ACEs are inherited by what is made in
/// it, so a file another library writes there is private from its first byte. No owner
/// or group: Windows makes the writer the owner.
pub fn secret_descriptor(writer: &Sid, folder: bool) -> Descriptor {
    let flags = if folder {
        OBJECT_INHERIT_ACE | CONTAINER_INHERIT_ACE
    } else {
        0
    };
    let mut holders: Vec<Sid> = SECRET_HOLDERS.iter().map(|s| Sid::known(s)).collect();
    if !holders.contains(writer) {
        holders.push(writer.clone());
    }
    Descriptor {
        owner: None,
        group: None,
        dacl: Some(
            holders
                .into_iter()
                .map(|sid| Ace {
                    allow: true,
                    flags,
                    mask: FILE_ALL_ACCESS,
                    sid,
                })
                .collect(),
        ),
        protected: true,
    }
}

/// Rights that read a file's data: `FILE_READ_DATA`, `GENERIC_READ`, `GENERIC_ALL`.
const READS: u32 = 0x0000_0001 | 0x8000_0000 | 0x1000_0000;

/// What in the descriptor of a file of secrets is weaker than allowed, one sentence each:
/// no DACL; an allow ACE for anyone but [`SECRET_HOLDERS`], the file's owner and `also`
/// (the service's account); ACEs inherited from the folder; a DACL that is not protected
/// (what the folder passes on would reach it). Deny ACEs narrow, so they are never a
/// finding. Empty: private.
pub fn secret_findings(d: &Descriptor, also: &[Sid]) -> Vec<String> {
    let Some(aces) = &d.dacl else {
        return vec!["no DACL: everyone may read and change it".into()];
    };
    let names = [
        (EVERYONE, "Everyone"),
        (USERS, "Users"),
        (AUTHENTICATED_USERS, "Authenticated Users"),
        (ANONYMOUS, "ANONYMOUS LOGON"),
        (INTERACTIVE, "INTERACTIVE"),
        (NETWORK, "NETWORK"),
    ];
    let allowed = |sid: &Sid| {
        SECRET_HOLDERS.iter().any(|h| Sid::known(h) == *sid)
            || d.owner.as_ref() == Some(sid)
            || also.contains(sid)
    };
    let mut out = Vec::new();
    for a in aces
        .iter()
        .filter(|a| a.allow && a.mask != 0 && !allowed(&a.sid))
    {
        let who = match names.iter().find(|(s, _)| Sid::known(s) == a.sid) {
            Some((_, name)) => format!("{name} ({})", a.sid),
            None => a.sid.to_string(),
        };
        let what = if a.mask & READS != 0 {
            "may read it"
        } else {
            "has rights on it"
        };
        out.push(format!("{who} {what} ({:#x})", a.mask));
    }
    let inherited = aces.iter().filter(|a| a.inherited()).count();
    if inherited > 0 {
        out.push(format!(
            "{inherited} of its {} ACEs are inherited from its folder",
            aces.len()
        ));
    } else if !d.protected {
        out.push("its DACL is not protected: what its folder passes on reaches it".into());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// S-1-5-32-544 (MS-DTYP 2.4.2.4, BUILTIN_ADMINISTRATORS): revision 1, 2
    /// sub-authorities, authority 5 (NT) big-endian, 32 and 544 little-endian.
    const BA: [u8; 16] = [1, 2, 0, 0, 0, 0, 0, 5, 32, 0, 0, 0, 0x20, 0x02, 0, 0];
    /// S-1-5-18 (LOCAL_SYSTEM).
    const SY: [u8; 12] = [1, 1, 0, 0, 0, 0, 0, 5, 18, 0, 0, 0];

    #[test]
    fn sids_parse_to_the_spec_bytes_and_back() {
        assert_eq!(Sid::parse(ADMINISTRATORS).unwrap().as_bytes(), BA);
        assert_eq!(Sid::parse(SYSTEM).unwrap().as_bytes(), SY);
        assert_eq!(
            Sid::parse(EVERYONE).unwrap().as_bytes(),
            [1, 1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0]
        );
        let domain = "S-1-5-21-3623811015-3361044348-30300820-1013";
        assert_eq!(Sid::parse(domain).unwrap().to_string(), domain);
        assert_eq!(Sid::from_bytes(&BA).unwrap().to_string(), ADMINISTRATORS);
        for bad in [
            "",
            "S-1",
            "S-2-5-18",
            "X-1-5-18",
            "S-1-5-x",
            "S-1-281474976710656-1",
        ] {
            assert_eq!(Sid::parse(bad), None, "{bad}");
        }
        assert_eq!(Sid::from_bytes(&BA[..15]), None);
        assert_eq!(Sid::from_bytes(&[2, 0, 0, 0, 0, 0, 0, 5]), None);
    }

    /// `O:BAG:BAD:(A;;CCDC;;;SY)` worked out by hand from MS-DTYP 2.4.6 / 2.4.5 / 2.4.4.2:
    /// header (revision 1, control SE_SELF_RELATIVE|SE_DACL_PRESENT = 0x8004, owner at
    /// 0x30, group at 0x40, no SACL, DACL at 0x14), the ACL (revision 2, size 0x1C, one
    /// ACE), the ACE (type 0, size 0x14, mask 3, SID SY), then owner and group BA.
    #[test]
    fn one_ace_descriptor_byte_for_byte() {
        let d = Descriptor {
            owner: Some(Sid::known(ADMINISTRATORS)),
            group: Some(Sid::known(ADMINISTRATORS)),
            dacl: Some(vec![Ace::allow(Sid::known(SYSTEM), ACCESS_LOCAL)]),
            protected: false,
        };
        let mut want = vec![
            1, 0, 0x04, 0x80, // revision, sbz1, control
            0x30, 0, 0, 0, // owner
            0x40, 0, 0, 0, // group
            0, 0, 0, 0, // no SACL
            0x14, 0, 0, 0, // DACL
            2, 0, 0x1C, 0, 1, 0, 0, 0, // ACL header
            0, 0, 0x14, 0, 3, 0, 0, 0, // ACE header and mask
        ];
        want.extend_from_slice(&SY);
        want.extend_from_slice(&BA);
        want.extend_from_slice(&BA);
        assert_eq!(d.to_bytes(), want);
        assert_eq!(Descriptor::from_bytes(&want), Some(d.clone()));
        assert_eq!(
            d.sddl(),
            "O:S-1-5-32-544G:S-1-5-32-544D:(A;;0x3;;;S-1-5-18)"
        );
    }

    /// The default launch descriptor with the clients' group, by hand: five ACEs,
    /// `O:BAG:BAD:(A;;CCDCSW;;;BA)(A;;CCDCSW;;;SY)(A;;CCDCSW;;;IU)(A;;CCDCSW;;;LS)
    /// (A;;CCDCLCSWRP;;;<group>)`.
    #[test]
    fn the_default_launch_descriptor_byte_for_byte() {
        let group = Sid::parse("S-1-5-21-1-2-3-1001").unwrap();
        let d = default_launch(true, Some(&group));
        let b = d.to_bytes();
        // ACEs: BA 8+16, SY 8+12, IU 8+12, LS 8+12, group 8+28 = 24+20+20+20+36 = 120;
        // ACL 8+120 = 128 (0x80); owner at 20+128 = 0x94, group at 0xA4; total 0xB4.
        assert_eq!(b.len(), 0xB4);
        assert_eq!(
            &b[..20],
            &[1, 0, 4, 0x80, 0x94, 0, 0, 0, 0xA4, 0, 0, 0, 0, 0, 0, 0, 0x14, 0, 0, 0]
        );
        assert_eq!(&b[20..28], &[2, 0, 0x80, 0, 5, 0, 0, 0]);
        // The first ACE: allow, size 24, mask 0xB, BA.
        assert_eq!(&b[28..36], &[0, 0, 24, 0, 0x0B, 0, 0, 0]);
        assert_eq!(&b[36..52], &BA);
        // The group's ACE: size 36, mask 0x1F.
        assert_eq!(&b[112..120], &[0, 0, 36, 0, 0x1F, 0, 0, 0]);
        assert_eq!(&b[0x94..0xA4], &BA);
        assert_eq!(Descriptor::from_bytes(&b), Some(d.clone()));
        let masks: Vec<(String, u32)> = d
            .dacl
            .unwrap()
            .iter()
            .map(|a| (a.sid.to_string(), a.mask))
            .collect();
        assert_eq!(
            masks,
            [
                ("S-1-5-32-544".to_owned(), 0xB),
                ("S-1-5-18".to_owned(), 0xB),
                ("S-1-5-4".to_owned(), 0xB),
                ("S-1-5-19".to_owned(), 0xB),
                ("S-1-5-21-1-2-3-1001".to_owned(), 0x1F),
            ]
        );
    }

    #[test]
    fn access_defaults_are_local_except_for_the_clients_group() {
        let d = default_access(false, None);
        let aces = d.dacl.as_ref().unwrap();
        assert_eq!(aces.len(), 3, "no service account, no group");
        assert!(aces.iter().all(|a| a.mask == ACCESS_LOCAL));
        assert!(weaker_than_default(&d, None).is_empty());
        let group = Sid::parse("S-1-5-21-9-1001").unwrap();
        let d = default_access(true, Some(&group));
        assert_eq!(d.dacl.as_ref().unwrap().last().unwrap().mask, ACCESS_REMOTE);
        assert!(weaker_than_default(&d, Some(&group)).is_empty());
    }

    #[test]
    fn what_is_weaker_than_the_defaults_is_named() {
        let open = Descriptor {
            owner: None,
            group: None,
            dacl: Some(vec![
                Ace::allow(Sid::known(EVERYONE), ACCESS_REMOTE),
                Ace::allow(Sid::known(ADMINISTRATORS), LAUNCH_REMOTE),
                Ace {
                    allow: false,
                    flags: 0,
                    mask: ACCESS_REMOTE,
                    sid: Sid::known(ANONYMOUS),
                },
            ]),
            protected: false,
        };
        let w = weaker_than_default(&open, None);
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(
            w[0].starts_with("Everyone (S-1-1-0) is allowed 0x7"),
            "{}",
            w[0]
        );
        assert!(
            w[1].starts_with("S-1-5-32-544 has remote rights (0x1f)"),
            "{}",
            w[1]
        );
        let null = Descriptor {
            owner: None,
            group: None,
            dacl: None,
            protected: false,
        };
        assert_eq!(weaker_than_default(&null, None).len(), 1);
        let b = null.to_bytes();
        assert_eq!(
            b,
            [1, 0, 0, 0x80, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]
        );
        assert_eq!(Descriptor::from_bytes(&b), Some(null));
        assert!(authentication_level_weaker(None));
        assert!(authentication_level_weaker(Some(2)));
        assert!(!authentication_level_weaker(Some(5)));
        assert!(!authentication_level_weaker(Some(6)));
    }

    #[test]
    fn garbage_is_not_a_descriptor() {
        assert_eq!(Descriptor::from_bytes(&[]), None);
        assert_eq!(Descriptor::from_bytes(&[1, 0, 4, 0]), None);
        let mut b = default_access(false, None).to_bytes();
        b[3] = 0; // not self-relative
        assert_eq!(Descriptor::from_bytes(&b), None);
        let mut b = default_access(false, None).to_bytes();
        b[22] = 0xFF; // ACL size past the end
        assert_eq!(Descriptor::from_bytes(&b), None);
        for n in 0..b.len() {
            let _ = Descriptor::from_bytes(&b[..n]);
        }
    }

    #[test]
    fn appid_defaults_cover_both_views() {
        let v = appid_defaults(crate::CLSID_SERVERCTOPC, false, None);
        assert_eq!(v.len(), 6);
        for view in crate::VIEWS {
            let names: Vec<&str> = v
                .iter()
                .filter(|d| d.view == view)
                .map(|d| d.name)
                .collect();
            assert_eq!(
                names,
                [ACCESS_PERMISSION, LAUNCH_PERMISSION, AUTHENTICATION_LEVEL]
            );
        }
        assert!(v
            .iter()
            .all(|d| d.path == "AppID\\{3277B556-BA68-4BDE-8687-8EE4E4B46336}"));
        assert_eq!(v[2].data, Data::Dword(5));
        assert_eq!(
            v[0].data,
            Data::Binary(default_access(false, None).to_bytes())
        );
    }

    fn sddl_aces(d: &Descriptor) -> Vec<(String, u8, u32)> {
        d.dacl
            .iter()
            .flatten()
            .map(|a| (a.sid.to_string(), a.flags, a.mask))
            .collect()
    }

    #[test]
    fn secret_descriptors_are_protected_full_control_for_the_holders_and_the_writer() {
        let writer = Sid::parse("S-1-5-21-7-8-9-1001").unwrap();
        let file = secret_descriptor(&writer, false);
        assert!(file.protected);
        assert_eq!((file.owner.as_ref(), file.group.as_ref()), (None, None));
        assert_eq!(
            sddl_aces(&file),
            [
                ("S-1-5-18".to_owned(), 0, FILE_ALL_ACCESS),
                ("S-1-5-32-544".to_owned(), 0, FILE_ALL_ACCESS),
                ("S-1-5-19".to_owned(), 0, FILE_ALL_ACCESS),
                ("S-1-5-21-7-8-9-1001".to_owned(), 0, FILE_ALL_ACCESS),
            ]
        );
        // The control word: self-relative, DACL present and protected (0x9004); the ACE
        // flags and the protection survive the bytes.
        let b = file.to_bytes();
        assert_eq!(&b[2..4], &[0x04, 0x90]);
        assert_eq!(Descriptor::from_bytes(&b), Some(file.clone()));
        // On disk the writer owns it.
        let on_disk = Descriptor {
            owner: Some(writer.clone()),
            ..file.clone()
        };
        assert!(secret_findings(&on_disk, &[]).is_empty());
        assert_eq!(
            secret_findings(&file, &[]),
            ["S-1-5-21-7-8-9-1001 may read it (0x1f01ff)"]
        );
        // A folder's ACEs go to files and folders made in it; the writer SYSTEM is not
        // named twice.
        let folder = secret_descriptor(&Sid::known(SYSTEM), true);
        let aces = sddl_aces(&folder);
        assert_eq!(aces.len(), 3);
        assert!(aces.iter().all(|(_, f, _)| *f == 0x3), "{aces:?}");
        assert_eq!(
            Descriptor::from_bytes(&folder.to_bytes()),
            Some(folder.clone())
        );
        assert!(secret_findings(&folder, &[]).is_empty());
    }

    /// The rule as a table: the ACEs (SID, flags, mask; mask 0: a deny ACE of full
    /// control) and protection of a file's DACL, the service account the caller also
    /// allows, and the findings.
    #[test]
    fn what_is_weaker_than_a_secret_allows_is_named() {
        const OWNER: &str = "S-1-5-21-1-2-3-1001";
        const OTHER: &str = "S-1-5-21-1-2-3-1002";
        const SERVICE: &str = "S-1-5-80-1-2-3-4-5";
        const READ: u32 = 0x0012_00A9;
        fn full(s: &'static str) -> (&'static str, u8, u32) {
            (s, 0, FILE_ALL_ACCESS)
        }
        type Row<'a> = (&'a [(&'a str, u8, u32)], bool, &'a [&'a str], &'a [&'a str]);
        let table: &[Row] = &[
            // What ServerCTOPC writes.
            (
                &[
                    full(SYSTEM),
                    full(ADMINISTRATORS),
                    full(LOCAL_SERVICE),
                    full(OWNER),
                ],
                true,
                &[],
                &[],
            ),
            // The service's own account, given by the caller.
            (&[full(SYSTEM), full(SERVICE)], true, &[SERVICE], &[]),
            (
                &[full(SYSTEM), full(SERVICE)],
                true,
                &[],
                &["S-1-5-80-1-2-3-4-5 may read it (0x1f01ff)"],
            ),
            // A deny ACE narrows: never a finding.
            (&[(EVERYONE, 0, 0)], true, &[], &[]),
            // What Windows gives a file made in an ordinary folder.
            (
                &[
                    (SYSTEM, INHERITED_ACE, FILE_ALL_ACCESS),
                    (USERS, INHERITED_ACE, READ),
                ],
                false,
                &[],
                &[
                    "Users (S-1-5-32-545) may read it (0x1200a9)",
                    "2 of its 2 ACEs are inherited from its folder",
                ],
            ),
            (
                &[(EVERYONE, 0, READ)],
                true,
                &[],
                &["Everyone (S-1-1-0) may read it (0x1200a9)"],
            ),
            (
                &[(AUTHENTICATED_USERS, 0, 0x8000_0000)],
                true,
                &[],
                &["Authenticated Users (S-1-5-11) may read it (0x80000000)"],
            ),
            (
                &[(OTHER, 0, 0x2)],
                true,
                &[],
                &["S-1-5-21-1-2-3-1002 has rights on it (0x2)"],
            ),
            (
                &[full(SYSTEM)],
                false,
                &[],
                &["its DACL is not protected: what its folder passes on reaches it"],
            ),
        ];
        for (aces, protected, also, want) in table {
            let d = Descriptor {
                owner: Some(Sid::known(OWNER)),
                group: None,
                dacl: Some(
                    aces.iter()
                        .map(|(sid, flags, mask)| Ace {
                            allow: *mask != 0,
                            flags: *flags,
                            mask: if *mask == 0 { FILE_ALL_ACCESS } else { *mask },
                            sid: Sid::known(sid),
                        })
                        .collect(),
                ),
                protected: *protected,
            };
            let also: Vec<Sid> = also.iter().map(|s| Sid::known(s)).collect();
            assert_eq!(secret_findings(&d, &also), *want, "{}", d.sddl());
        }
        let null = Descriptor {
            owner: None,
            group: None,
            dacl: None,
            protected: true,
        };
        assert_eq!(
            secret_findings(&null, &[]),
            ["no DACL: everyone may read and change it"]
        );
    }
}
