// Who holds what at the relay, by peer name: the vehicle seat (the one vehicle whose video the
// relay analyses and forwards, and whose channels get the goals), the operator seat (the one
// client driving by hand, docs/contracts.md "Data-channel details") and the watchers (the clients
// that can see the robot: the autopilot drives only while there is one). A peer's departure
// frees only the seats that peer held: a second vehicle that came and went must not take the
// first one's place with it. Pure: names in, decisions out; tested directly
// (e2e/test_relay_seats_js.py).

/** One seat, held by at most one peer at a time. */
export class Seat {
  /** @param {string} what the seat's name in refusals, e.g. 'the vehicle seat' */
  constructor(what) {
    this.what = what;
    this.holder = null;
  }

  /** Take the seat for `name`: null when it is (now, or already) theirs, else why not. */
  claim(name) {
    if (this.holder !== null && this.holder !== name) return `${this.holder} holds ${this.what}`;
    this.holder = name;
    return null;
  }

  /** `name` is gone: true when it held the seat, which is free from now on. */
  release(name) {
    if (this.holder === null || this.holder !== name) return false;
    this.holder = null;
    return true;
  }
}

/**
 * The operator seat: a client takes the wheel from the autopilot, drives, and hands it back;
 * nobody else drives meanwhile. The vehicle numbers each operator's drive commands afresh, so
 * the numbering restarts with every change of holder.
 */
export class OperatorSeat {
  #seat = new Seat('the wheel');
  #driveSeq = 0;

  /** The client holding the wheel, or null: the autopilot steers. */
  get holder() {
    return this.#seat.holder;
  }

  /** The mode message for the seat as it stands (to the vehicle and every client). */
  modeMessage(reason = null) {
    const operator = this.holder;
    return {
      type: 'mode',
      mode: operator === null ? 'auto' : 'manual',
      operator,
      ...(reason ? { reason } : {}),
    };
  }

  /**
   * `name` asks for the wheel: {changed: true} when it is theirs now, {changed: false} when it
   * already was, {refused: reason} when someone else holds it.
   */
  takeOver(name) {
    if (this.holder === name) return { changed: false };
    if (this.holder !== null) {
      return { refused: `${this.holder} is driving; take over once they hand back or leave` };
    }
    this.#hold(name);
    return { changed: true };
  }

  /** `name` hands the wheel back to the autopilot: null when done, else why not. */
  handBack(name) {
    if (this.holder !== name) {
      return this.holder === null
        ? 'nobody holds the wheel'
        : `${this.holder} holds the wheel, not ${name}`;
    }
    this.#hold(null);
    return null;
  }

  /**
   * `name`'s drive command {linear, angular}: {drive} renumbered for the vehicle when `name`
   * holds the wheel, else {refused: reason}.
   */
  drive(name, { linear, angular }) {
    if (this.holder !== name) {
      return {
        refused:
          this.holder === null
            ? 'take over before driving'
            : `${this.holder} is driving, not ${name}`,
      };
    }
    this.#driveSeq += 1;
    return { drive: { type: 'drive', seq: this.#driveSeq, linear, angular } };
  }

  /** The robot was stopped: the wheel goes back to the autopilot. Returns who held it, or null. */
  takeBack() {
    const holder = this.holder;
    if (holder !== null) this.#hold(null);
    return holder;
  }

  /** `name` is gone: true when it held the wheel (the autopilot has it back). */
  leave(name) {
    if (this.holder !== name || name === null) return false;
    this.#hold(null);
    return true;
  }

  #hold(name) {
    if (name === null) this.#seat.release(this.holder);
    else this.#seat.claim(name);
    this.#driveSeq = 0;
  }
}

/**
 * The clients watching the robot: each client in the room whose link to the relay has not
 * dropped. A client counts from the moment it is in the room (its link is being set up, or it
 * pilots through signaling alone), stops counting when it leaves or its link drops (its control
 * channel closed, its connection failed), and counts again when its link comes back. Each
 * change answers whether it left nobody watching where somebody was: the moment the relay
 * stops piloting (docs/contracts.md).
 */
export class Watchers {
  #inRoom = new Set();
  #dropped = new Set(); // in the room, link dropped

  /** The names of the clients watching, in the order they came. */
  get names() {
    return [...this.#inRoom].filter((name) => !this.#dropped.has(name));
  }

  /** The room's clients are now `names` (the roster): true when that left nobody watching. */
  room(names) {
    return this.#change(() => {
      this.#inRoom = new Set(names);
      for (const name of this.#dropped) if (!this.#inRoom.has(name)) this.#dropped.delete(name);
    });
  }

  /** `name`'s link to the relay is up (its control channel opened). */
  linkUp(name) {
    this.#dropped.delete(name);
  }

  /** `name`'s link to the relay dropped: true when that left nobody watching. */
  linkDown(name) {
    return this.#change(() => {
      if (this.#inRoom.has(name)) this.#dropped.add(name);
    });
  }

  #change(apply) {
    const before = this.names.length;
    apply();
    return before > 0 && this.names.length === 0;
  }
}
