// Which ROS type names to use on a robot: the ones its rosapi reports, else the `ros=` setting.
// The type tables come from app/protocol (ros.py, robot.py) through the page's embedded config
// (`config.rosTypes`, `config.robot.types`); this mirrors app.protocol.robot.detect.

/**
 * @param {{default: string, types: Object<string, Object<string, string>>}} rosTypes
 * @param {{description: Object, types: {pose: Object<string, string>,
 *   velocity: Object<string, string>, velocityKinds: Object<string, string>}}} robot
 * @param {string} setting 'auto', '1', '2' or 'jazzy'
 * @param {string|null} poseReported rosapi topic_type of the pose topic (null: no answer)
 * @param {string|null} velocityReported rosapi topic_type of the velocity topic (null: no answer)
 */
export function pickTypes(rosTypes, robot, setting, poseReported, velocityReported) {
  const table = robot.types;
  const reported = Object.keys(table.pose).find((f) => table.pose[f] === poseReported);
  const flavour = reported ?? (setting === 'auto' ? rosTypes.default : setting);
  // A velocity type the robot reports (a Twist or a TwistStamped) is used as reported: the
  // robot's graph is the truth, and a command in the other type would not reach it.
  const kind = velocityReported ? table.velocityKinds[velocityReported] : undefined;
  return {
    flavour,
    fromRobot: reported !== undefined,
    pose: table.pose[flavour],
    velocity: kind === undefined ? table.velocity[flavour] : velocityReported,
    velocityKind: kind ?? robot.description.velocity.type,
    teleport: rosTypes.types[flavour].teleportAbsolute,
  };
}
