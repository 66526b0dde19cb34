// The fleet page: polls /fleet/rooms and redraws one row per room.
import { byTestId, fmt, show } from '../view/ui.js';

const table = byTestId('fleet-table');
const rows = byTestId('fleet-rows');
const REFRESH_MS = Number(table.dataset.refreshMs);
// The token of the URL's fragment (`/fleet#token=…`): a fleet token (`autopilot token --role
// fleet`) shows every room, a room's token that room alone; the server asks for one when access
// control is on. The fragment never reaches the server's log.
const TOKEN = new URLSearchParams(location.hash.slice(1)).get('token');
const HEADERS = TOKEN ? { Authorization: `Bearer ${TOKEN}` } : {};

/** Read-only for tests: the rooms last shown and how many refreshes succeeded. */
const status = { rooms: [], refreshes: 0 };
window.autopilotStatus = status;

function cell(text) {
  const td = document.createElement('td');
  td.textContent = text;
  return td;
}

function piloting(row) {
  if (row.piloting === null) return '–';
  return row.piloting ? 'yes' : 'no';
}

function render(rooms) {
  rows.replaceChildren(
    ...rooms.map((row) => {
      const tr = document.createElement('tr');
      tr.dataset.room = row.room;
      const link = document.createElement('a');
      link.href = row.client_url;
      link.textContent = 'client page';
      const linkCell = document.createElement('td');
      linkCell.append(link);
      tr.append(
        cell(row.room),
        cell(row.vehicles.join(', ') || '–'),
        cell(row.relay ?? '–'),
        cell(row.pool ?? '–'),
        cell(row.clients.join(', ') || '–'),
        cell(piloting(row)),
        cell(row.op ?? '–'),
        cell(fmt(row.goals_per_s)),
        cell(fmt(row.ms_per_snapshot)),
        linkCell,
      );
      return tr;
    }),
  );
}

async function refresh() {
  try {
    const response = await fetch('/fleet/rooms', { cache: 'no-store', headers: HEADERS });
    if (response.status === 401) {
      const how = 'open /fleet#token=<token> (autopilot token --role fleet)';
      throw new Error(`a token is needed: ${how}`);
    }
    if (!response.ok) throw new Error(`HTTP ${response.status}`);
    status.rooms = await response.json();
    status.refreshes += 1;
    render(status.rooms);
    const rooms = `${status.rooms.length} room${status.rooms.length === 1 ? '' : 's'}`;
    show('fleet-state', `${rooms} · updated ${new Date().toLocaleTimeString()}`);
  } catch (err) {
    show('fleet-state', `cannot load the rooms: ${err.message}`);
  } finally {
    setTimeout(refresh, REFRESH_MS);
  }
}

refresh();
