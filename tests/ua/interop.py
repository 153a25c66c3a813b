"""OPC UA interoperability of ServerCTOPC with an independent client (Python asyncua).

Run by `cargo xtask ua-interop` (which builds the server and makes the venv):

    python interop.py --server target/debug/ServerCTOPC --db demo/.../wytwornia_kwasu.zez --work DIR

It writes a configuration in DIR (the demo plant simulated in process, [UA] on a free
loopback port), adds a writer and a reader user with `ServerCTOPC user add`, starts
`ServerCTOPC serve` and checks, over Basic256Sha256 SignAndEncrypt:
- an untrusted client certificate is refused and saved in pki/rejected; after
  `ServerCTOPC pki trust` it is accepted;
- browse (Objects -> ServerCTOPC -> the groups -> the variables; in pages with BrowseNext),
  read (values, the
  variable's attributes, the EURange property), write as the writer (read back),
  Bad_NotWritable for a read-only variable, subscribe (data changes arrive; an absolute
  deadband larger than the range, and a percent deadband of 100 % of EURange, let only
  the first one through);
- the derived values: FormatedCV, PercentageCV and BarCVs are components of KW_A000 whose
  NodeIds are their item IDs, read (a text, a number, two numbers) and subscribed;
- `_Diagnostics`: a folder first under ServerCTOPC (Server, Clients, Channels), its
  variables read Good;
- the Server object: ServerStatus (State Running, StartTime, CurrentTime, BuildInfo
  naming ServerCTOPC and its version) and ServerDiagnosticsSummary (the session and
  subscription counts);
- the reader's write is Bad_UserAccessDenied; anonymous, a wrong password and
  SecurityPolicy None are refused;
- texts in the session's locale: sessions with LocaleIds `pl`, `en` and `de, pl-PL` read
  a variable's, a derived value's, a `_Diagnostics` folder's and item's Description and
  a property's DisplayName (read and browsed) in Polish, English and Polish, each with
  its locale;
- services: RegisterNodes (the registered NodeIds read) and UnregisterNodes, the Value of
  a variable, an unknown node and a folder in one Read and one CreateMonitoredItems (Good,
  Bad_NodeIdUnknown, Bad_AttributeIdInvalid), ModifyMonitoredItems (5 s to 100 ms:
  revised, and the changes come at the new rate), Republish
  (an unknown sequence number is Bad_MessageNotAvailable), TransferSubscriptions to a
  second session of the same user, a monitored item's queue of 3 with DiscardOldest true
  and false while the value changes faster than the publishing (publishing off, then on);
- limits (small ones in the test's [UA] section): sessions, subscriptions per session,
  monitored items per subscription and in all, browse continuation points, operations per
  request, the request rate, a string over MaxStringLength: each is answered with its
  Bad_ code and the server goes on serving;
- the server stops on SIGTERM with exit code 0;
- secrets at rest: the users file and the private key made at first start are 0600 (the
  key's folder 0700), and the server's log of the whole run, at TRACE for every crate,
  holds no password, no password hash and no line of the private key.

Every wait has a deadline. The last line is `N passed, M failed`.
"""

import argparse
import asyncio
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from asyncua import Client, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.x509.oid import ExtendedKeyUsageOID

NAMESPACE_URI = "urn:askom:ServerCTOPC"
CLIENT_URI = "urn:ctopc:interop:client"
PASSWORDS = {"writer1": "pisarz-hasło-1", "reader1": "czytelnik-hasło-2"}

passed = 0
failed = 0


def check(name, ok, detail=""):
    global passed, failed
    if ok:
        passed += 1
        print(f"ok   {name}")
    else:
        failed += 1
        print(f"FAIL {name} {detail}")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_port(port, proc, deadline):
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return False
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1):
                return True
        except OSError:
            time.sleep(0.1)
    return False


def client(url, user=None):
    c = Client(url, timeout=20)
    c.application_uri = CLIENT_URI
    if user:
        c.set_user(user)
        c.set_password(PASSWORDS.get(user, "wrong"))
    return c


async def secure(c, cert, key, mode=ua.MessageSecurityMode.SignAndEncrypt):
    await c.set_security(
        SecurityPolicyBasic256Sha256, certificate=str(cert), private_key=str(key), mode=mode
    )


async def refused(name, make):
    """The connection `make()` builds must fail."""
    c = await make()
    try:
        await c.connect()
    except Exception as e:  # refused: what asyncua raises varies with the stage
        check(name, True)
        return str(e)
    else:
        check(name, False, "connected")
        await c.disconnect()
        return None


class Changes:
    def __init__(self):
        self.values = []

    def datachange_notification(self, node, val, data):
        self.values.append((val, data.monitored_item.Value.StatusCode))


async def wait_for(cond, seconds):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if cond():
            return True
        await asyncio.sleep(0.05)
    return cond()


async def scenario(url, work, server):
    pki = work / "pki"
    cert = work / "client-cert.der"
    key = work / "client-key.pem"
    await setup_self_signed_certificate(
        key, cert, CLIENT_URI, "localhost", [ExtendedKeyUsageOID.CLIENT_AUTH],
        {"countryName": "PL", "organizationName": "ctopc", "commonName": "interop"},
    )

    async def writer():
        c = client(url, "writer1")
        await secure(c, cert, key)
        return c

    # 1. An unknown client certificate is refused and saved in pki/rejected.
    await refused("untrusted client certificate refused", writer)
    rejected = sorted((pki / "rejected").glob("*"))
    check("the refused certificate is saved in pki/rejected", len(rejected) == 1, str(rejected))
    if not rejected:
        return
    r = subprocess.run([server, "pki", "trust", str(rejected[0])], capture_output=True, text=True)
    check("pki trust moves it to pki/trusted", r.returncode == 0 and len(list((pki / "trusted").glob("*"))) == 1,
          r.stderr)

    # 2. The writer, over Basic256Sha256 SignAndEncrypt.
    c = await writer()
    async with c:
        ns = await c.get_namespace_index(NAMESPACE_URI)
        check("our namespace is in the namespace array", ns > 0, str(ns))
        objects = c.nodes.objects
        names = {(await n.read_browse_name()).Name: n for n in await objects.get_children()}
        check("Objects organizes ServerCTOPC", "ServerCTOPC" in names, str(list(names)))
        root = names["ServerCTOPC"]
        groups = {(await n.read_browse_name()).Name: n for n in await root.get_children()}
        check("ServerCTOPC lists the plant's groups", "Magazyn siarki" in groups, str(list(groups)))
        tanks = {(await n.read_browse_name()).Name: n for n in await groups["Magazyn siarki"].get_children()}
        tank = tanks.get("Zbiornik siarki ciekłej Z101")
        variables = [(await n.read_browse_name()).Name for n in await tank.get_children()] if tank else []
        check("browsing reaches the variables", variables == ["KW_A000", "KW_A001", "KW_A002"], str(variables))

        # Browse with continuation points: two references at a time, then BrowseNext.
        desc = ua.BrowseDescription()
        desc.NodeId = root.nodeid
        desc.BrowseDirection = ua.BrowseDirection.Forward
        desc.ReferenceTypeId = ua.NodeId(ua.ObjectIds.HierarchicalReferences)
        desc.IncludeSubtypes = True
        desc.NodeClassMask = 0
        desc.ResultMask = ua.BrowseResultMask.All
        params = ua.BrowseParameters()
        params.View.Timestamp = ua.get_win_epoch()
        params.RequestedMaxReferencesPerNode = 2
        params.NodesToBrowse = [desc]
        first = (await c.uaclient.browse(params))[0]
        paged = [r.BrowseName.Name for r in first.References]
        cp = first.ContinuationPoint
        pages = 1
        while cp and pages < 100:
            nxt = ua.BrowseNextParameters()
            nxt.ReleaseContinuationPoints = False
            nxt.ContinuationPoints = [cp]
            res = (await c.uaclient.browse_next(nxt))[0]
            paged += [r.BrowseName.Name for r in res.References]
            cp = res.ContinuationPoint
            pages += 1
        check("browse in pages of 2 with BrowseNext lists every group once",
              len(first.References) == 2 and sorted(paged) == sorted(groups), f"{pages} pages: {paged}")

        a000 = c.get_node(ua.NodeId("KW_A000", ns))
        dv = await a000.read_data_value()
        check("read: a Float with status Good", isinstance(dv.Value.Value, float) and dv.StatusCode.is_good(),
              str(dv))
        dn = await a000.read_display_name()
        check("read: DisplayName", dn.Text == "KW_A000", str(dn))
        typedef = await a000.read_type_definition()
        check("KW_A000 is an AnalogItemType", typedef == ua.NodeId(ua.ObjectIds.AnalogItemType), str(typedef))
        eu = await (await a000.get_child(["0:EURange"])).read_value()
        check("read: EURange of KW_A000 is 0..8", (eu.Low, eu.High) == (0.0, 8.0), str(eu))
        level = await a000.read_attribute(ua.AttributeIds.AccessLevel)
        check("KW_A000 is read-only", level.Value.Value == 1, str(level))

        a110 = c.get_node(ua.NodeId("KW_A110", ns))
        await a110.write_value(ua.DataValue(ua.Variant(12.5, ua.VariantType.Float)))
        back = await a110.read_value()
        check("write as the writer, read back", back == 12.5, str(back))
        try:
            await a000.write_value(ua.DataValue(ua.Variant(1.0, ua.VariantType.Float)))
            check("write of a read-only variable refused", False, "accepted")
        except ua.UaStatusCodeError as e:
            check("write of a read-only variable is Bad_NotWritable",
                  e.code == ua.StatusCodes.BadNotWritable, hex(e.code))

        # Subscriptions: data changes arrive; a huge absolute deadband passes the first only.
        changes = Changes()
        sub = await c.create_subscription(200, changes)
        await sub.subscribe_data_change(c.get_node(ua.NodeId("KW_A001", ns)))
        # Part 4 lets the first notification be Bad_WaitingForInitialData when the item is
        # sampled before the source's first value; everything after it must be Good.
        def settled():
            vals = changes.values
            if vals and vals[0][1].value == ua.StatusCodes.BadWaitingForInitialData:
                vals = vals[1:]
            return vals
        got = await wait_for(lambda: len(settled()) >= 3, 20)
        check("subscription: data changes of KW_A001 arrive", got, str(changes.values[:4]))
        check("subscription: values are Good (an initial Bad_WaitingForInitialData allowed)",
              all(s.is_good() and v is not None for v, s in settled()[:3]), str(changes.values[:4]))
        banded = Changes()
        sub2 = await c.create_subscription(200, banded)
        await sub2.deadband_monitor(c.get_node(ua.NodeId("KW_A001", ns)), 1.0e9, deadbandtype=1)
        before = len(changes.values)
        await wait_for(lambda: len(changes.values) >= before + 3, 20)
        check("absolute deadband: only the first value passes", len(banded.values) == 1,
              f"{len(banded.values)} notifications while the unfiltered item got {len(changes.values) - before}")
        # A percent deadband of 100 % of EURange (the server finds EURange itself).
        percent = Changes()
        sub3 = await c.create_subscription(200, percent)
        await sub3.deadband_monitor(c.get_node(ua.NodeId("KW_A001", ns)), 100.0, deadbandtype=2)
        before = len(changes.values)
        await wait_for(lambda: len(changes.values) >= before + 3, 20)
        check("percent deadband (of EURange): only the first value passes", len(percent.values) == 1,
              f"{len(percent.values)} notifications while the unfiltered item got {len(changes.values) - before}")
        await server_object(c)
        await sub.delete()
        await sub2.delete()
        await sub3.delete()

        await derived_values(c, ns, a000)
        await diagnostics_folder(c, ns, root)

    # 3. The reader: reads, but its write is refused.
    c = client(url, "reader1")
    await secure(c, cert, key)
    async with c:
        ns = await c.get_namespace_index(NAMESPACE_URI)
        node = c.get_node(ua.NodeId("KW_A110", ns))
        check("the reader reads", (await node.read_value()) == 12.5)
        try:
            await node.write_value(ua.DataValue(ua.Variant(3.0, ua.VariantType.Float)))
            check("the reader's write is refused", False, "accepted")
        except ua.UaStatusCodeError as e:
            check("the reader's write is Bad_UserAccessDenied",
                  e.code == ua.StatusCodes.BadUserAccessDenied, hex(e.code))

    # 4. What is refused.
    async def anonymous():
        c = client(url)
        await secure(c, cert, key)
        return c

    async def wrong_password():
        c = Client(url, timeout=20)
        c.application_uri = CLIENT_URI
        c.set_user("writer1")
        c.set_password("not the password")
        await secure(c, cert, key)
        return c

    async def no_security():
        return client(url, "writer1")

    await refused("anonymous refused", anonymous)
    await refused("a wrong password refused", wrong_password)
    await refused("SecurityPolicy None refused", no_security)

    await locales(url, cert, key)
    await services(url, cert, key)
    await limits(url, cert, key)


# What each language's session reads: KW_A000's Description (KW_A000.FormatedCV has the
# same), the DisplayName of its property ItemEUType, the Descriptions of the folder
# _Diagnostics.Server and of the item _Diagnostics.Server.Uptime.
TEXTS = {
    "pl": ("Poziom siarki ciekłej w zbiorniku Z101", "Typ jednostek inżynierskich elementu",
           "Liczniki serwera", "Czas pracy serwera od startu"),
    "en": ("Liquid sulphur level in tank Z101", "Item EU Type",
           "The server's counters", "Time since the server started"),
}


async def locales(url, cert, key):
    """Description and DisplayName in the session's locale (ActivateSession's LocaleIds):
    the first of them that names Polish or English; the LocalizedText's locale says which."""
    for ids, lang in [(["pl"], "pl"), (["en"], "en"), (["de", "pl-PL"], "pl")]:
        description, eu_type, server, uptime = TEXTS[lang]
        c = client(url, "reader1")
        c.set_locale(ids)
        await secure(c, cert, key)
        async with c:
            ns = await c.get_namespace_index(NAMESPACE_URI)
            node = lambda i: c.get_node(ua.NodeId(i, ns))

            def text(t):
                return (t.Locale, t.Text)
            a000 = node("KW_A000")
            got = text(await a000.read_description())
            check(f"locale {ids}: KW_A000's Description in {lang}", got == (lang, description), str(got))
            got = text(await node("KW_A000.FormatedCV").read_description())
            check(f"locale {ids}: KW_A000.FormatedCV's Description in {lang}", got == (lang, description),
                  str(got))
            got = text(await (await a000.get_child(["0:ItemEUType"])).read_display_name())
            check(f"locale {ids}: the property ItemEUType's DisplayName in {lang}", got == (lang, eu_type),
                  str(got))
            refs = await a000.get_references(refs=ua.ObjectIds.HasProperty)
            browsed = {r.BrowseName.Name: text(r.DisplayName) for r in refs}
            check(f"locale {ids}: browsed, ItemEUType's DisplayName in {lang}",
                  browsed.get("ItemEUType") == (lang, eu_type), str(browsed.get("ItemEUType")))
            got = text(await node("_Diagnostics.Server").read_description())
            check(f"locale {ids}: the folder _Diagnostics.Server's Description in {lang}",
                  got == (lang, server), str(got))
            got = text(await node("_Diagnostics.Server.Uptime").read_description())
            check(f"locale {ids}: _Diagnostics.Server.Uptime's Description in {lang}", got == (lang, uptime),
                  str(got))


# The small limits of the test's [UA] section (main() writes them), checked by limits().
LIMITS = {
    "MaxSessions": 5,
    "MaxSubscriptionsPerSession": 4,
    "MaxMonitoredItemsPerSubscription": 5,
    "MaxMonitoredItems": 8,
    "MaxBrowseContinuationPoints": 2,
    "MaxOperationsPerRequest": 50,
    "MaxStringLength": 8192,
    "MaxRequestsPerSecond": 100,
}


def status_of(e):
    """The status code of an asyncua error, or None."""
    return getattr(e, "code", None)


async def send(c, request, response_type):
    """A request asyncua has no helper for: its response, or the status code of the
    ServiceFault it was answered with."""
    from asyncua.ua.ua_binary import struct_from_binary
    try:
        data = await c.uaclient.protocol.send_request(request)
    except ua.UaStatusCodeError as e:
        return e.code
    return struct_from_binary(response_type, data)


async def services(url, cert, key):
    async def writer():
        c = client(url, "writer1")
        await secure(c, cert, key)
        return c

    c = await writer()
    async with c:
        # asyncua's publish loop ends when the session's last subscription is deleted, and
        # one created just then may be left without Publish requests: this one stays.
        await c.create_subscription(1000, Changes())
        ns = await c.get_namespace_index(NAMESPACE_URI)
        nodes = [c.get_node(ua.NodeId(n, ns)) for n in ("KW_A000", "KW_A110")]
        registered = await c.register_nodes(nodes)
        values = [await n.read_value() for n in registered]
        check("RegisterNodes: the registered NodeIds read",
              len(registered) == 2 and all(isinstance(v, float) for v in values), str(values))
        await c.unregister_nodes(registered)
        check("UnregisterNodes answers Good", True)

        # The Value of a variable, of an unknown node and of a folder in one Read, and as
        # monitored items of one CreateMonitoredItems: each node its own answer.
        names = ("KW_A000", "NO_SUCH_VARIABLE", "_Diagnostics")
        expected = [ua.StatusCodes.Good, ua.StatusCodes.BadNodeIdUnknown,
                    ua.StatusCodes.BadAttributeIdInvalid]
        targets = [ua.ReadValueId(NodeId_=ua.NodeId(n, ns), AttributeId=ua.AttributeIds.Value)
                   for n in names]
        params = ua.ReadParameters()
        params.NodesToRead = targets
        got = [dv.StatusCode_.value for dv in await c.uaclient.read(params)]
        check("Read of Values: a variable Good, an unknown node Bad_NodeIdUnknown, "
              "a folder Bad_AttributeIdInvalid", got == expected, str(got))
        sub = await c.create_subscription(1000, Changes())
        items = [ua.MonitoredItemCreateRequest(
            ItemToMonitor=t, MonitoringMode_=ua.MonitoringMode.Reporting,
            RequestedParameters=ua.MonitoringParameters(ClientHandle=i + 1, SamplingInterval=1000.0,
                                                        QueueSize=1, DiscardOldest=True))
            for i, t in enumerate(targets)]
        req = ua.CreateMonitoredItemsRequest()
        req.Parameters = ua.CreateMonitoredItemsParameters(
            SubscriptionId=sub.subscription_id, TimestampsToReturn_=ua.TimestampsToReturn.Both,
            ItemsToCreate=items)
        res = await send(c, req, ua.CreateMonitoredItemsResponse)
        got = res if isinstance(res, int) else [
            r.StatusCode_.value for r in res.Results]
        check("CreateMonitoredItems of Values: a variable Good, an unknown node "
              "Bad_NodeIdUnknown, a folder Bad_AttributeIdInvalid", got == expected, str(got))
        await sub.delete()

        # ModifyMonitoredItems: an item sampled every 5 s made 100 ms is Good, revised to
        # 100 ms, and its variable's changes then come at the new rate.
        got = Changes()
        sub = await c.create_subscription(100, got)
        handle = await sub.subscribe_data_change(c.get_node(ua.NodeId("KW_A001", ns)),
                                                 sampling_interval=5000)
        await wait_for(lambda: len(got.values) >= 1, 20)
        res = await sub.modify_monitored_item(handle, 100.0)
        check("ModifyMonitoredItems: Good, the sampling interval revised to 100 ms",
              len(res) == 1 and res[0].StatusCode_.is_good()
              and res[0].RevisedSamplingInterval == 100.0, str(res))
        before = len(got.values)
        await wait_for(lambda: len(got.values) >= before + 3, 3)
        check("ModifyMonitoredItems: the changes come at the new rate (3 within 3 s)",
              len(got.values) >= before + 3, str(len(got.values) - before))
        await sub.delete()

        # Republish of a sequence number the server never sent.
        changes = Changes()
        sub = await c.create_subscription(100, changes)
        await sub.subscribe_data_change(c.get_node(ua.NodeId("KW_A001", ns)))
        await wait_for(lambda: len(changes.values) >= 1, 20)
        req = ua.RepublishRequest()
        req.Parameters = ua.RepublishParameters(SubscriptionId=sub.subscription_id,
                                                RetransmitSequenceNumber=0x7FFF0000)
        res = await send(c, req, ua.RepublishResponse)
        check("Republish of an unknown message is Bad_MessageNotAvailable",
              res == ua.StatusCodes.BadMessageNotAvailable, str(res))
        await sub.delete()

        # A monitored item's queue of 3: six values written while publishing is off.
        kept = {}
        a110 = c.get_node(ua.NodeId("KW_A110", ns))
        for oldest in (True, False):
            got = Changes()
            sub = await c.create_subscription(100, got)
            params = ua.MonitoringParameters(ClientHandle=1, SamplingInterval=0.0, QueueSize=3,
                                             DiscardOldest=oldest)
            item = ua.MonitoredItemCreateRequest(
                ItemToMonitor=ua.ReadValueId(NodeId_=a110.nodeid, AttributeId=ua.AttributeIds.Value),
                MonitoringMode_=ua.MonitoringMode.Reporting, RequestedParameters=params)
            await a110.write_value(ua.DataValue(ua.Variant(100.0, ua.VariantType.Float)))
            await sub.create_monitored_items([item])
            await wait_for(lambda: any(v == 100.0 for v, _ in got.values), 20)
            await sub.set_publishing_mode(False)
            before = len(got.values)
            for v in range(101, 107):
                await a110.write_value(ua.DataValue(ua.Variant(float(v), ua.VariantType.Float)))
                # Apart by more than the sampling interval: each value is its own sample.
                await asyncio.sleep(0.35)
            await sub.set_publishing_mode(True)
            await wait_for(lambda: len(got.values) >= before + 3, 20)
            kept[oldest] = [v for v, _ in got.values[before:]]
            await sub.delete()
        check("queue of 3, DiscardOldest: the newest three are delivered",
              kept[True] == [104.0, 105.0, 106.0], str(kept[True]))
        # The first two queued are 101 and 102, or the item's first sample of 100 (the
        # engine may sample the value it already had) and 101.
        check("queue of 3, DiscardOldest false: the first two and the newest are delivered",
              kept[False] in ([101.0, 102.0, 106.0], [100.0, 101.0, 106.0]), str(kept[False]))

        # TransferSubscriptions: a second session of the same user takes the subscription over.
        sub = await c.create_subscription(100, Changes())
        await sub.subscribe_data_change(c.get_node(ua.NodeId("KW_A001", ns)))
        c2 = await writer()
        async with c2:
            req = ua.TransferSubscriptionsRequest()
            req.Parameters = ua.TransferSubscriptionsParameters(
                SubscriptionIds=[sub.subscription_id], SendInitialValues=True)
            res = await send(c2, req, ua.TransferSubscriptionsResponse)
            results = [] if isinstance(res, int) else (res.Parameters.Results or [])
            check("TransferSubscriptions to a second session is Good",
                  len(results) == 1 and results[0].StatusCode_.is_good(), str(res))
            # Now the second session's: it deletes it, the first one no longer can.
            req = ua.DeleteSubscriptionsRequest()
            req.Parameters = ua.DeleteSubscriptionsParameters(SubscriptionIds=[sub.subscription_id])
            res = await send(c2, req, ua.DeleteSubscriptionsResponse)
            deleted = [] if isinstance(res, int) else [r.value for r in res.Results]
            check("the transferred subscription belongs to the second session (it deletes it)",
                  deleted == [ua.StatusCodes.Good], str(res))


async def limits(url, cert, key):
    async def writer():
        c = client(url, "writer1")
        await secure(c, cert, key)
        return c

    # MaxSessions: sessions are opened until one is refused (a refused login's session
    # may still count until it times out), at most MaxSessions of them.
    held = []
    why = None
    try:
        for _ in range(LIMITS["MaxSessions"] + 1):
            c = await writer()
            try:
                await c.connect()
            except Exception as e:
                why = str(e)
                break
            held.append(c)
        check("a session past MaxSessions is refused with Bad_TooManySessions",
              why is not None and "TooManySessions" in why and len(held) <= LIMITS["MaxSessions"],
              f"{len(held)} sessions held, then {why}")
    finally:
        for c in held:
            await c.disconnect()

    c = await writer()
    async with c:
        ns = await c.get_namespace_index(NAMESPACE_URI)
        items = [c.get_node(ua.NodeId(f"KW_A{n:03}", ns)) for n in (0, 1, 2, 110, 111, 112)]

        # MaxSubscriptionsPerSession.
        subs = [await c.create_subscription(500, Changes()) for _ in range(LIMITS["MaxSubscriptionsPerSession"])]
        try:
            subs.append(await c.create_subscription(500, Changes()))
            check("a subscription past MaxSubscriptionsPerSession refused", False, "created")
        except ua.UaStatusCodeError as e:
            check("a subscription past MaxSubscriptionsPerSession is Bad_TooManySubscriptions",
                  status_of(e) == ua.StatusCodes.BadTooManySubscriptions, hex(status_of(e) or 0))

        # MaxMonitoredItemsPerSubscription: six items in one subscription of at most five.
        try:
            handles = await subs[0].subscribe_data_change(items)
            bad = [h for h in handles if isinstance(h, ua.StatusCode)]
            check("monitored items past MaxMonitoredItemsPerSubscription are Bad_TooManyMonitoredItems",
                  bad and all(h.value == ua.StatusCodes.BadTooManyMonitoredItems for h in bad), str(handles))
        except ua.UaStatusCodeError as e:
            check("monitored items past MaxMonitoredItemsPerSubscription are Bad_TooManyMonitoredItems",
                  status_of(e) == ua.StatusCodes.BadTooManyMonitoredItems, hex(status_of(e) or 0))
        # MaxMonitoredItems in all (8): five in one subscription, four in another.
        for s in subs:
            await s.delete()
        a = await c.create_subscription(500, Changes())
        b = await c.create_subscription(500, Changes())
        first = await a.subscribe_data_change(items[:5])
        second = []
        try:
            second = await b.subscribe_data_change(items[:4])
        except ua.UaStatusCodeError as e:
            second = [ua.StatusCode(status_of(e))]
        refused_items = [h for h in second if isinstance(h, ua.StatusCode)]
        check("monitored items past MaxMonitoredItems (every subscription's) are Bad_TooManyMonitoredItems",
              all(isinstance(h, int) for h in first) and len(refused_items) == 1
              and refused_items[0].value == ua.StatusCodes.BadTooManyMonitoredItems, f"{first} {second}")
        await a.delete()
        await b.delete()
        again = await c.create_subscription(500, Changes())
        back = await again.subscribe_data_change(items[:5])
        check("deleted monitored items are given back to MaxMonitoredItems",
              all(isinstance(h, int) for h in back), str(back))
        await again.delete()

        # MaxBrowseContinuationPoints (2): three nodes browsed one reference at a time.
        root = (await c.nodes.objects.get_child([f"{ns}:ServerCTOPC"]))
        groups = await root.get_children()
        descs = []
        for g in groups[:3]:
            d = ua.BrowseDescription()
            d.NodeId = g.nodeid
            d.BrowseDirection = ua.BrowseDirection.Forward
            d.ReferenceTypeId = ua.NodeId(ua.ObjectIds.HierarchicalReferences)
            d.IncludeSubtypes = True
            d.ResultMask = ua.BrowseResultMask.All
            descs.append(d)
        params = ua.BrowseParameters()
        params.View.Timestamp = ua.get_win_epoch()
        params.RequestedMaxReferencesPerNode = 1
        params.NodesToBrowse = descs
        results = await c.uaclient.browse(params)
        codes = [r.StatusCode.value for r in results]
        check("a continuation point past MaxBrowseContinuationPoints is Bad_NoContinuationPoints",
              len(descs) == 3 and codes.count(ua.StatusCodes.BadNoContinuationPoints) == 1, str(codes))
        release = ua.BrowseNextParameters()
        release.ReleaseContinuationPoints = True
        release.ContinuationPoints = [r.ContinuationPoint for r in results if r.ContinuationPoint]
        await c.uaclient.browse_next(release)

        # MaxOperationsPerRequest (50): a Read of 51 nodes.
        many = [c.get_node(ua.NodeId("KW_A000", ns))] * (LIMITS["MaxOperationsPerRequest"] + 1)
        try:
            await c.read_values(many)
            check("a Read past MaxOperationsPerRequest refused", False, "read")
        except ua.UaStatusCodeError as e:
            check("a Read past MaxOperationsPerRequest is Bad_TooManyOperations",
                  status_of(e) == ua.StatusCodes.BadTooManyOperations, hex(status_of(e) or 0))

        # MaxRequestsPerSecond (100): 1,500 Reads at once; some are refused, none fails otherwise.
        node = c.get_node(ua.NodeId("KW_A000", ns))

        async def one():
            try:
                await node.read_value()
                return 0
            except ua.UaStatusCodeError as e:
                return status_of(e)
        outcomes = await asyncio.gather(*[one() for _ in range(1500)])
        over = outcomes.count(ua.StatusCodes.BadTooManyOperations)
        check("Reads past MaxRequestsPerSecond are Bad_TooManyOperations, the rest Good",
              over > 0 and all(o in (0, ua.StatusCodes.BadTooManyOperations) for o in outcomes),
              f"{outcomes.count(0)} Good, {over} refused, others {set(outcomes) - {0, ua.StatusCodes.BadTooManyOperations}}")
        # The bucket refills: a second later a Read is Good again.
        await asyncio.sleep(1.1)
        check("after a second the session reads again", isinstance(await node.read_value(), float))

    # MaxStringLength (8192): a Write of a longer string is refused; the server goes on.
    c = await writer()
    try:
        async with c:
            ns = await c.get_namespace_index(NAMESPACE_URI)
            try:
                await c.get_node(ua.NodeId("KW_A110", ns)).write_value(
                    ua.DataValue(ua.Variant("x" * 20000, ua.VariantType.String)))
                check("a string past MaxStringLength refused", False, "written")
            except Exception as e:  # a status code, or the channel closed by the server
                check("a string past MaxStringLength refused", True, repr(e))
    except Exception:
        pass
    c = await writer()
    async with c:
        ns = await c.get_namespace_index(NAMESPACE_URI)
        check("the server still serves after every limit",
              isinstance(await c.get_node(ua.NodeId("KW_A000", ns)).read_value(), float))


async def derived_values(c, ns, a000):
    """FormatedCV, PercentageCV and BarCVs: components of KW_A000 named by their item IDs,
    read and subscribed like any variable."""
    children = {}
    for n in await a000.get_children(refs=ua.ObjectIds.HasComponent):
        children[(await n.read_browse_name()).Name] = n
    names = ("FormatedCV", "PercentageCV", "BarCVs")
    for name in names:
        node = children.get(name)
        check(f"KW_A000 has the component {name}, its NodeId the item ID KW_A000.{name}",
              node is not None and node.nodeid == ua.NodeId(f"KW_A000.{name}", ns), str(children))
    if not all(n in children for n in names):
        return
    text, percent, bars = [await children[n].read_data_value() for n in names]
    check("read: FormatedCV is a text, Good", isinstance(text.Value.Value, str) and text.Value.Value != ""
          and text.StatusCode.is_good(), str(text))
    check("read: PercentageCV is a number, Good", isinstance(percent.Value.Value, float)
          and percent.StatusCode.is_good(), str(percent))
    check("read: BarCVs is two numbers, Good", isinstance(bars.Value.Value, list) and len(bars.Value.Value) == 2
          and bars.StatusCode.is_good(), str(bars))
    parent = await children["PercentageCV"].get_parent()
    check("PercentageCV names KW_A000 as its parent", parent is not None and parent.nodeid == a000.nodeid,
          str(parent))
    changes = Changes()
    sub = await c.create_subscription(200, changes)
    await sub.subscribe_data_change(children["PercentageCV"])

    def good():
        return [v for v, s in changes.values if s.is_good() and isinstance(v, float)]
    got = await wait_for(lambda: len(good()) >= 1, 20)
    check("subscription: Good data changes of KW_A000.PercentageCV arrive", got, str(changes.values[:4]))
    await sub.delete()


async def diagnostics_folder(c, ns, root):
    """`_Diagnostics`: a folder first under ServerCTOPC, its sections folders, its items
    variables read Good."""
    first = (await root.get_children(refs=ua.ObjectIds.Organizes))[0]
    check("_Diagnostics is the first folder under ServerCTOPC", first.nodeid == ua.NodeId("_Diagnostics", ns)
          and (await first.read_node_class()) == ua.NodeClass.Object, str(first))
    sections = [(await n.read_browse_name()).Name for n in await first.get_children()]
    check("_Diagnostics holds Server, Clients, Channels", sections == ["Server", "Clients", "Channels"],
          str(sections))
    server = c.get_node(ua.NodeId("_Diagnostics.Server", ns))
    fields = {(await n.read_browse_name()).Name: n for n in await server.get_children()}
    clients = fields.get("Clients")
    check("_Diagnostics.Server lists Uptime and Clients", "Uptime" in fields and clients is not None,
          str(list(fields)))
    if clients is None:
        return
    dv = await clients.read_data_value()
    check("read: _Diagnostics.Server.Clients is Good, at least the UA front end",
          dv.StatusCode.is_good() and isinstance(dv.Value.Value, int) and dv.Value.Value >= 1, str(dv))
    desc = await clients.read_description()
    check("_Diagnostics.Server.Clients has a description", bool(desc.Text), str(desc))


async def server_object(c):
    """The Server object's ServerStatus and ServerDiagnosticsSummary, read while the
    caller's three subscriptions exist."""
    ids = ua.ObjectIds
    node = lambda i: c.get_node(ua.NodeId(i, 0))
    state = await node(ids.Server_ServerStatus_State).read_value()
    check("ServerStatus.State is Running", state == ua.ServerState.Running, str(state))
    start = await node(ids.Server_ServerStatus_StartTime).read_value()
    now = await node(ids.Server_ServerStatus_CurrentTime).read_value()
    check("ServerStatus: StartTime before CurrentTime", start is not None and now is not None
          and start.year > 2000 and start <= now, f"{start} {now}")
    product = await node(ids.Server_ServerStatus_BuildInfo_ProductName).read_value()
    check("BuildInfo.ProductName is ServerCTOPC", product == "ServerCTOPC", str(product))
    version = await node(ids.Server_ServerStatus_BuildInfo_SoftwareVersion).read_value()
    check("BuildInfo.SoftwareVersion is set", bool(version), str(version))
    uri = await node(ids.Server_ServerStatus_BuildInfo_ProductUri).read_value()
    check("BuildInfo.ProductUri", uri == NAMESPACE_URI, str(uri))
    sessions = await node(ids.Server_ServerDiagnostics_ServerDiagnosticsSummary_CurrentSessionCount).read_value()
    check("ServerDiagnosticsSummary.CurrentSessionCount counts this session", sessions >= 1, str(sessions))
    subs = await node(ids.Server_ServerDiagnostics_ServerDiagnosticsSummary_CurrentSubscriptionCount).read_value()
    check("ServerDiagnosticsSummary.CurrentSubscriptionCount counts this session's subscriptions",
          subs >= 3, str(subs))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--server", required=True)
    p.add_argument("--db", required=True)
    p.add_argument("--work", required=True)
    a = p.parse_args()
    work = Path(a.work).resolve()
    work.mkdir(parents=True, exist_ok=True)
    for old in ("pki", "ua-users.txt"):
        path = work / old
        if path.is_dir():
            import shutil
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()
    port = free_port()
    ini = work / "ASIXConnect.ini"
    ini.write_text(
        # Sampling at 100 ms: the queue checks write faster than the publishing, each
        # value its own sample.
        "[Server]\nSimulateCurrentData = tak\nMinUpdateRate = 100\n"
        f"[Channel:*]\nItemsDatabase = {Path(a.db).resolve()}\n"
        f"[UA]\nEndpoint = opc.tcp://127.0.0.1:{port}\n"
        + "".join(f"{k} = {v}\n" for k, v in LIMITS.items()),
        encoding="utf-8",
    )
    env = dict(os.environ, SERVERCTOPC_INI=str(ini))
    user_add_output = ""
    for user, role in (("writer1", "writer"), ("reader1", "reader")):
        r = subprocess.run([a.server, "user", "add", user, "--role", role, "--password-stdin"],
                           input=PASSWORDS[user] + "\n", capture_output=True, text=True, env=env)
        check(f"user add {user}", r.returncode == 0, r.stderr)
        user_add_output += r.stdout + r.stderr
    log = open(work / "serve.log", "w")
    # The most verbose log there is (every crate at TRACE), so that the check of secrets in
    # it below covers every level.
    proc = subprocess.Popen([a.server, "serve"], env=dict(env, RUST_LOG="trace"), stdout=log,
                            stderr=subprocess.STDOUT)
    os.environ["SERVERCTOPC_INI"] = str(ini)
    try:
        up = wait_port(port, proc, time.monotonic() + 120)
        check("serve listens", up)
        if up:
            asyncio.run(asyncio.wait_for(scenario(f"opc.tcp://127.0.0.1:{port}", work, a.server), 300))
    except Exception as e:
        check("the scenario ran to its end", False, repr(e))
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        try:
            code = proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            code = proc.wait()
        check("serve stops on SIGTERM with exit code 0", code == 0, f"exit code {code}")
        log.close()
    secrets_at_rest(work, user_add_output)
    if failed:
        print(f"--- {work / 'serve.log'} (last lines)")
        print("".join(open(work / "serve.log", encoding="utf-8", errors="replace").readlines()[-40:]))
    print(f"{passed} passed, {failed} failed")
    sys.exit(1 if failed else 0)


def secrets_at_rest(work, user_add_output):
    """The users file and the private key made at first start are owner-only (0600, the
    key's folder 0700), and no secret is in the TRACE log of the run nor in `user add`'s
    output: not a password, not a password hash of the users file, not a line of the
    private key's PEM body."""
    key = work / "pki" / "private" / "private.pem"
    users = work / "ua-users.txt"
    for path, want in ((users, 0o600), (key, 0o600), (key.parent, 0o700)):
        mode = path.stat().st_mode & 0o777 if path.exists() else None
        check(f"{path.relative_to(work)} is owner-only ({want:o})", mode == want,
              f"mode {mode:o}" if mode is not None else "missing")
    text = open(work / "serve.log", encoding="utf-8", errors="replace").read() + user_add_output
    secrets = [(f"the password of {u}", p) for u, p in PASSWORDS.items()]
    for line in users.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#") and line.count(":") >= 5:
            secrets.append((f"the hash of {line.split(':')[0]}", line.rsplit(":", 1)[1]))
    body = [l for l in key.read_text().splitlines() if l and not l.startswith("-----")]
    secrets += [("a line of the private key", l) for l in body if len(l) >= 16]
    leaked = [what for what, s in secrets if s in text]
    check(f"no secret in the TRACE log ({len(text.splitlines())} lines, {len(secrets)} secrets "
          "looked for)", bool(body) and not leaked, ", ".join(sorted(set(leaked))))


if __name__ == "__main__":
    main()
