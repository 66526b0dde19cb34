// The page's configuration, embedded by the server as JSON in <script id="config">
// (app/server/pages.py, its shape app/protocol/page.py) and parsed here once. `CONFIG.protocol`
// holds the protocol's constants and data-channel schemas, `CONFIG.control` the control law's
// numbers and the world's size: modules import them from here and never type a profile name,
// channel label, world size or tag layout again.

function readConfig() {
  const element = document.getElementById('config');
  if (element === null) throw new Error('this page has no #config (see app/server/pages.py)');
  const config = JSON.parse(element.textContent);
  if (config.protocol === undefined) {
    throw new Error('this page has no config.protocol (see app/server/pages.py)');
  }
  config.token = new URLSearchParams(location.hash.slice(1)).get('token');
  // A token in the query has already gone to the server (and its access log): not used, but
  // recognised, so that the page can say where it belongs.
  config.tokenInQuery = config.token === null && new URLSearchParams(location.search).has('token');
  return config;
}

/**
 * The page's config: {room, name, role, profile, ..., protocol}, plus the token from the URL
 * fragment (`#token=…`): a fragment never leaves the browser, so the token stays out of every
 * request line and access log.
 */
export const CONFIG = readConfig();
/**
 * {roles, defaultRoom, profiles: {relay, vehicle}, defaultProfile,
 *  relayProfiles: {name: {snapshotPeriodMs}}, channels: {autopilot, autopilotState, control},
 *  stateChannelOptions, goalFreshness, video: {width, height}, clientForwardScaleDown,
 *  frameTag: {blocksPerWidth, markerBlocks, bits}, lock: {searchAfterS, releaseAfterS, maxScale,
 *  reach}, health: {periodS, maxLossPct, maxRttMs}, opencvBuild: 'simd'|'official',
 *  schemas: {label: {role: JSON Schema}}}
 */
export const PROTOCOL = CONFIG.protocol;
export const CHANNELS = PROTOCOL.channels;
export const SCHEMAS = PROTOCOL.schemas;
