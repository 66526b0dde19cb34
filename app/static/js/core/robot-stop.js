// The relay's Stop robot, told once per stop: a press while the robot stands stopped and nothing
// has moved it since (no piloting, nobody at the wheel) changes nothing, so nobody is told again
// -- 500 presses are one stop, not 500 messages to every client. Tested in
// e2e/test_robot_stop_js.py.

export class RobotStop {
  #standing = null; // the robotStopped message of the stop that stands, or null

  /**
   * A Stop robot press by `by` (a client's name, or null: the relay itself) for `reason`;
   * `moving`: whether anything drives the robot now (piloting, or an operator at the wheel).
   * @returns {{type: 'robotStopped', by: string | null, reason: string} | null} the message to
   *   tell everyone and act on, or null when the robot stands stopped already
   */
  press(by, reason, moving) {
    if (!moving && this.#standing !== null) return null;
    this.#standing = { type: 'robotStopped', by, reason };
    return this.#standing;
  }

  /** Piloting started again: the stop no longer stands. */
  clear() {
    this.#standing = null;
  }

  /** The robotStopped message while that stop stands, or null. */
  get standing() {
    return this.#standing;
  }
}
