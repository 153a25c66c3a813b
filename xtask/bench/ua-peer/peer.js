// The peer OPC UA server of `cargo xtask bench --ua`: node-opcua serving the synthetic
// variable set of asix_model::synthetic (crates/asix-model/src/synthetic.rs) as ServerCTOPC
// serves it, so that one load client measures both alike:
// - the namespace urn:askom:ServerCTOPC; under Objects the folder ServerCTOPC, then
//   "Obszar NNN" (100 sections each), "Sekcja NNNNN" (100 variables each);
// - variable i: NodeId ns=<that namespace>;s=T<i, 7 digits> (the alias, ServerCTOPC's DA
//   item ID), browse name the same, Int16 when i % 10 == 9, else Float;
// - values: every variable but the writable ones (i % 5 == 0, constant in the simulation)
//   changes every 250 ms, the in-process simulation's plant tick; the value is a function
//   of the tick, read by node-opcua when it samples;
// - endpoints: SecurityPolicy None and Basic256Sha256 SignAndEncrypt; user name and password
//   (one user, from the environment variables UA_PEER_USER and UA_PEER_PASSWORD), no
//   anonymous sessions; client certificates accepted (the bench client's is new each run).
//
// usage: node peer.js --port PORT --size N --pki DIR
// Prints "listening on opc.tcp://127.0.0.1:PORT" when it serves; runs until SIGTERM/SIGINT.
"use strict";

const path = require("path");
const {
    OPCUAServer,
    OPCUACertificateManager,
    Variant,
    DataType,
    SecurityPolicy,
    MessageSecurityMode,
    nodesets,
} = require("node-opcua");

const TICK_MS = 250;
const BRANCH_SIZE = 100;
const AREA_SIZE = 100;

function arg(name, fallback) {
    const i = process.argv.indexOf(name);
    return i >= 0 && i + 1 < process.argv.length ? process.argv[i + 1] : fallback;
}

const port = Number(arg("--port", "4841"));
const size = Number(arg("--size", "1000"));
const pki = path.resolve(arg("--pki", "peer-pki"));
const user = process.env.UA_PEER_USER || "bench";
const password = process.env.UA_PEER_PASSWORD || "";

function pad(n, width) {
    return String(n).padStart(width, "0");
}

async function main() {
    const serverCertificateManager = new OPCUACertificateManager({
        automaticallyAcceptUnknownCertificate: true,
        rootFolder: path.join(pki, "server"),
    });
    const userCertificateManager = new OPCUACertificateManager({
        automaticallyAcceptUnknownCertificate: true,
        rootFolder: path.join(pki, "user"),
    });
    const server = new OPCUAServer({
        port,
        hostname: "127.0.0.1",
        alternateHostname: ["127.0.0.1"],
        resourcePath: "/",
        nodeset_filename: [nodesets.standard],
        securityPolicies: [SecurityPolicy.None, SecurityPolicy.Basic256Sha256],
        securityModes: [MessageSecurityMode.None, MessageSecurityMode.SignAndEncrypt],
        allowAnonymous: false,
        userManager: {
            isValidUser: (name, pass) => name === user && pass === password,
        },
        serverCertificateManager,
        userCertificateManager,
        maxSessions: 100,
        maxConnectionsPerEndpoint: 100,
        serverCapabilities: {
            maxBrowseContinuationPoints: 100,
            maxArrayLength: 1000000,
            operationLimits: {
                maxNodesPerRead: 10000,
                maxNodesPerBrowse: 1000,
                maxMonitoredItemsPerCall: 1000,
                maxNodesPerWrite: 10000,
                maxNodesPerRegisterNodes: 10000,
                maxNodesPerTranslateBrowsePathsToNodeIds: 10000,
            },
        },
        serverInfo: { applicationUri: "urn:bench:node-opcua-peer", productUri: "urn:bench:node-opcua-peer" },
    });
    await server.initialize();

    const addressSpace = server.engine.addressSpace;
    const ns = addressSpace.registerNamespace("urn:askom:ServerCTOPC");
    const top = ns.addFolder(addressSpace.rootFolder.objects, {
        browseName: "ServerCTOPC",
        nodeId: "s=ServerCTOPC",
    });
    let area = null;
    let section = null;
    for (let i = 0; i < size; i++) {
        const branch = Math.floor(i / BRANCH_SIZE);
        if (i % (BRANCH_SIZE * AREA_SIZE) === 0) {
            area = ns.addFolder(top, { browseName: `Obszar ${pad(Math.floor(branch / AREA_SIZE), 3)}` });
        }
        if (i % BRANCH_SIZE === 0) {
            section = ns.addFolder(area, { browseName: `Sekcja ${pad(branch, 5)}` });
        }
        const integral = i % 10 === 9;
        const constant = i % 5 === 0;
        const dataType = integral ? DataType.Int16 : DataType.Float;
        const name = `T${pad(i, 7)}`;
        ns.addVariable({
            componentOf: section,
            browseName: name,
            nodeId: `s=${name}`,
            dataType: integral ? "Int16" : "Float",
            minimumSamplingInterval: 50,
            value: {
                get: () => {
                    const tick = constant ? 0 : Math.floor(Date.now() / TICK_MS);
                    const v = integral ? (tick + i) % 100 : ((tick + i) % 1000) / 10;
                    return new Variant({ dataType, value: v });
                },
            },
        });
    }
    await server.start();
    console.log(`listening on opc.tcp://127.0.0.1:${port} (node-opcua, ${size} variables)`);
    const stop = async () => {
        await server.shutdown(0);
        process.exit(0);
    };
    process.on("SIGTERM", stop);
    process.on("SIGINT", stop);
}

main().catch((e) => {
    console.error(`peer: ${e && e.stack ? e.stack : e}`);
    process.exit(1);
});
