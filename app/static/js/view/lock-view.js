// The client page's side of the target lock (docs/architecture.md, "Which target"): a click
// on the video asks the relay to lock on the target at or near it (frame pixels, on the control
// channel), Unlock releases it, and the relay's lockState messages say how the lock stands and
// how to release it. The relay owns the lock (lock.js, snapshot-loop.js); this only asks and
// shows.

/**
 * The frame pixel under client point (clientX, clientY) of an element whose box is `rect` and
 * which shows a `w` × `h` frame letterboxed (object-fit: contain, as the video and its overlay),
 * or null when the point is on the letterbox bars.
 */
function framePoint(rect, clientX, clientY, w, h) {
  const scale = Math.min(rect.width / w, rect.height / h);
  const x = (clientX - rect.left - (rect.width - w * scale) / 2) / scale;
  const y = (clientY - rect.top - (rect.height - h * scale) / 2) / scale;
  if (x < 0 || y < 0 || x > w || y > h) return null;
  return { x, y };
}

const WORDS = {
  none: 'no lock: following the largest',
  locked: 'locked',
  lost: 'locked target lost: looking where it was',
  searching: 'locked target lost: searching the whole frame',
};

// While a lock holds, how to let go of it stays in view.
const RELEASE = 'Unlock, or a click where there is no face, releases it';

/** Words for a lockState message. */
function describeLock({ state, reason }) {
  const words = reason ? `${WORDS[state]} (${reason})` : WORDS[state];
  return state === 'none' ? words : `${words}; ${RELEASE}`;
}

/** Wires the video stage and the Unlock button to the relay, and shows the lock's state. */
export class LockPanel {
  /**
   * @param {object} options
   * @param {HTMLElement} options.stage the element the video and its overlay fill
   * @param {HTMLButtonElement} options.unlockButton
   * @param {(text: string) => void} options.showState
   * @param {(msg: object) => boolean} options.send sends on the control channel; false when closed
   * @param {() => object | null} options.frame the last detections ({w, h}), the frame clicked on
   * @param {{info: Function, error: Function}} options.log
   */
  constructor({ stage, unlockButton, showState, send, frame, log }) {
    this.unlockButton = unlockButton;
    this.showState = showState;
    this.send = send;
    this.log = log;
    this.state = null; // the relay's last lockState message
    stage.classList.add('lockable');
    stage.addEventListener('click', (event) => {
      const shown = frame();
      if (shown === null) return;
      const point = framePoint(
        stage.getBoundingClientRect(),
        event.clientX,
        event.clientY,
        shown.w,
        shown.h,
      );
      if (point !== null) this.#ask({ type: 'lock', x: point.x, y: point.y });
    });
    unlockButton.addEventListener('click', () => this.#ask({ type: 'unlock' }));
    this.onState({ state: 'none', box: null, reason: null });
  }

  /** The relay's lockState message ({state, box, reason}). */
  onState(msg) {
    this.state = msg;
    this.showState(describeLock(msg));
    this.unlockButton.disabled = msg.state === 'none';
  }

  #ask(msg) {
    if (!this.send(msg)) {
      this.log.error(`cannot ${msg.type}: no relay connection`);
      return;
    }
    this.log.info(
      msg.type === 'lock'
        ? `asked to lock at (${Math.round(msg.x)}, ${Math.round(msg.y)})`
        : 'asked to unlock',
    );
  }
}
