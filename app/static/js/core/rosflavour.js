// Which ROS type names to use on a robot: the ones its rosapi reports, else the `ros=` setting.
// The type table comes from app/protocol/ros.py through the page's embedded config
// (`config.rosTypes`); this mirrors app.protocol.ros.detect.

/**
 * @param {{default: string, types: Object<string, Object<string, string>>}} rosTypes
 * @param {string} setting 'auto', '1', '2' or 'jazzy'
 * @param {string|null} poseReported rosapi topic_type of /turtle1/pose (null: no answer)
 * @param {string|null} twistReported rosapi topic_type of /turtle1/cmd_vel (null: no answer)
 */
export function pickTypes(rosTypes, setting, poseReported, twistReported) {
  const reported = Object.keys(rosTypes.types).find((f) => rosTypes.types[f].pose === poseReported);
  const flavour = reported ?? (setting === 'auto' ? rosTypes.default : setting);
  const table = rosTypes.types[flavour];
  return {
    flavour,
    fromRobot: reported !== undefined,
    pose: table.pose,
    twist: twistReported || table.twist,
    teleport: table.teleportAbsolute,
  };
}
