// The robot's messages: its velocity command as rosbridge JSON, and its pose from a pose
// message. Twins of velocity_message, pose_of and yaw_of in app/protocol/robot.py, checked
// against them (e2e/test_robot_js.py); the robot's description (topics, types, limits) comes
// from there through the page's embedded config (`config.robot`).

const TWIST = 'geometry_msgs/Twist';
const TURTLESIM_POSE = 'turtlesim/Pose';

/**
 * A velocity command ({linear, angular}) as rosbridge JSON: a Twist, or a TwistStamped stamped
 * `stampS` (seconds since the epoch) in `frameId`, its time spelled as `flavour` spells it
 * (secs/nsecs in ROS 1, sec/nanosec in ROS 2).
 */
export function velocityMessage(kind, flavour, linear, angular, stampS, frameId) {
  const twist = { linear: { x: linear, y: 0, z: 0 }, angular: { x: 0, y: 0, z: angular } };
  if (kind === TWIST) return twist;
  const seconds = Math.floor(stampS);
  const nanoseconds = Math.min(999_999_999, Math.round((stampS - seconds) * 1e9));
  const stamp =
    flavour === '1'
      ? { secs: seconds, nsecs: nanoseconds }
      : { sec: seconds, nanosec: nanoseconds };
  return { header: { stamp, frame_id: frameId }, twist };
}

/**
 * The heading (rotation about z, in (−π, π]) of the quaternion (x, y, z, w), which need not be
 * normalised: both atan2 arguments scale with its squared norm. null for one with no heading.
 */
function yawOf(x, y, z, w) {
  const sine = 2 * (w * z + x * y);
  const cosine = w * w + x * x - y * y - z * z;
  if (!Number.isFinite(sine) || !Number.isFinite(cosine) || (sine === 0 && cosine === 0))
    return null;
  const yaw = Math.atan2(sine, cosine);
  // atan2 gives [−π, π]; the project's angles are (−π, π] (app/protocol/angles.py).
  return yaw === -Math.PI ? Math.PI : yaw;
}

const number = (value) => (typeof value === 'number' ? value : NaN);

/**
 * {x, y, theta} from a pose message of `kind`: a turtlesim/Pose's x, y and theta, an
 * Odometry's position and the yaw of its orientation; null for a message without them.
 */
export function poseOf(kind, message) {
  if (kind === TURTLESIM_POSE) {
    const pose = { x: number(message?.x), y: number(message?.y), theta: number(message?.theta) };
    return Object.values(pose).some(Number.isNaN) ? null : pose;
  }
  const pose = message?.pose?.pose;
  const q = pose?.orientation;
  const x = number(pose?.position?.x);
  const y = number(pose?.position?.y);
  if (Number.isNaN(x) || Number.isNaN(y) || q === undefined) return null;
  const theta = yawOf(number(q.x), number(q.y), number(q.z), number(q.w));
  return theta === null ? null : { x, y, theta };
}
