// The client's link-health panel: each link's round trip, loss, frame rate, size and candidate
// type (net/link-health.js measures them), the vehicle's goal age and the warnings on show.
import { byTestId, fmt, show } from './ui.js';

/**
 * Show `health` ({vehicleToRelay, relayToClient: each link's {rttMs, lossPct, fps, width,
 * height, candidate} or null, goalAgeMs, warnings}) in the panel.
 */
export function showLinkHealth(health) {
  for (const [id, figures] of [
    ['health-vehicle', health.vehicleToRelay],
    ['health-client', health.relayToClient],
  ]) {
    const cells = byTestId(id).querySelectorAll('td');
    const frames = figures?.width
      ? `${fmt(figures.fps, 1)} fps, ${figures.width}×${figures.height}`
      : '–';
    const values = [
      figures?.rttMs == null ? '–' : `${fmt(figures.rttMs, 0)} ms`,
      figures?.lossPct == null ? '–' : `${fmt(figures.lossPct, 1)} %`,
      frames,
      figures?.candidate ?? '–',
    ];
    values.forEach((text, i) => {
      cells[i].textContent = text;
    });
  }
  show(
    'goal-age',
    health.goalAgeMs === null
      ? 'no goal applied at the vehicle yet'
      : `last goal applied at the vehicle ${fmt(health.goalAgeMs, 0)} ms ago`,
  );
  show('health-warnings', health.warnings.join(' · '));
}
