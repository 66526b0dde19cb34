// The protocol constants and data-channel schemas, rendered by the server from app/protocol
// (app/protocol/browser.py) into every page's config as `config.protocol`. Modules import them
// from here and never type a profile name, channel label, world size or tag layout again.

function readProtocol() {
  const element = document.getElementById('config');
  const protocol = element === null ? undefined : JSON.parse(element.textContent).protocol;
  if (protocol === undefined) throw new Error('this page has no config.protocol (see app/server/pages.py)');
  return protocol;
}

/**
 * {roles, defaultRoom, profiles: {relay, vehicle}, defaultProfile, relayProfiles: {name: {snapshotPeriodMs}},
 *  channels: {autopilot, control}, world: {size, terrainCentre},
 *  frameTag: {blocksPerWidth, markerBlocks, bits}, lock: {searchAfterS, releaseAfterS, maxScale, reach},
 *  schemas: {label: {role: JSON Schema}}}
 */
export const PROTOCOL = readProtocol();
export const CHANNELS = PROTOCOL.channels;
export const WORLD = PROTOCOL.world;
export const SCHEMAS = PROTOCOL.schemas;
