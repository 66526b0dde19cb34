// The vehicle page's robot: a roslib.js connection to a rosbridge (the server's own /rosbridge
// or a robot's rosbridge_server), velocity commands out, pose in, and on a turtlesim the spawn
// step once. The robot's ROS types are learnt from its rosapi on every connection
// (core/rosflavour.js), its messages built and read by core/robot.js. ROSLIB is the vendored
// roslib.js, a classic script the vehicle page loads before its module.
import { pickTypes } from '../core/rosflavour.js';
import { poseOf, velocityMessage } from '../core/robot.js';

const ROS_RETRY_MS = 2000;

export class RobotLink {
  /**
   * `token`: sent as the rosbridge `auth` op, only to this server's own /rosbridge. `log`: the
   * page's log; `spawnTheta`: the heading the spawn step turns a turtlesim to (null: no step).
   */
  constructor(url, setting, rosTypes, robot, token, { log, spawnTheta }) {
    this.url = url;
    this.setting = setting;
    this.rosTypes = rosTypes;
    this.robot = robot; // config.robot: the description and its type names
    this.token = token;
    this.log = log;
    this.spawnTheta = spawnTheta;
    this.connected = false;
    this.types = null; // learnt on each connection
    this.typesFrom = null; // 'robot' (its rosapi named them) or 'setting' (the ros= fallback)
    this.ros = null;
    this.cmdVel = null;
    this.spawnDone = false;
    this.reported = false; // an outage has been logged
    this.badPoseLogged = false;
    this.onPose = () => {};
    // What the page shows of the connection: called with a line of text on every change.
    this.onState = () => {};
  }

  /** The page's token was renewed: prove the fresh one to rosbridge, which ends a session whose
   *  token expires (only where the old one was sent: this server's own /rosbridge). */
  renew(token) {
    if (!this.token) return;
    this.token = token;
    this.ros?.callOnConnection({ op: 'auth', token });
  }

  connect() {
    const ros = new ROSLIB.Ros({ url: this.url });
    this.ros = ros;
    // Queued for the moment the socket opens, ahead of the subscriptions made on 'connection'.
    if (this.token) ros.callOnConnection({ op: 'auth', token: this.token });
    ros.on('connection', () => {
      this.log.info(`rosbridge connected: ${this.url}`);
      this.reported = false;
      this.connected = true;
      this.onState('connected');
      this.#learnTypes(ros);
    });
    // roslib throws on an 'error' nobody listens to; the 'close' that follows is what we report.
    ros.on('error', () => {});
    ros.on('close', () => {
      if (this.ros !== ros) return;
      // Said once per outage, not on every retry.
      if (this.connected || !this.reported) {
        const retry = ROS_RETRY_MS / 1000;
        this.log.error(`rosbridge ${this.url} unreachable; retrying every ${retry} s`);
      }
      this.reported = true;
      this.connected = false;
      this.cmdVel = null;
      this.onState(`not connected (retrying every ${ROS_RETRY_MS / 1000} s)`);
      setTimeout(() => this.connect(), ROS_RETRY_MS);
    });
  }

  // The robot's own type names from rosapi topic_type; the ros= setting when it cannot say.
  async #learnTypes(ros) {
    const { velocity, pose } = this.robot.description;
    const [poseType, velocityType] = await Promise.all(
      [pose.topic, velocity.topic].map((topic) => this.#topicType(ros, topic)),
    );
    if (this.ros !== ros) return; // reconnected meanwhile
    const types = pickTypes(this.rosTypes, this.robot, this.setting, poseType, velocityType);
    this.types = types;
    this.typesFrom = types.fromRobot ? 'robot' : 'setting';
    const from = types.fromRobot
      ? 'as its rosapi reports'
      : `from ros=${this.setting}: rosapi did not say`;
    this.log.info(`ROS ${types.flavour} types (${types.pose}, ${types.velocity}) ${from}`);
    if (types.velocityKind !== velocity.type)
      this.log.warn(
        `${velocity.topic} is a ${types.velocityKind} on the robot, not a ${velocity.type}`,
      );
    this.onState(`connected (ROS ${types.flavour}, ${this.robot.description.name})`);
    this.cmdVel = new ROSLIB.Topic({ ros, name: velocity.topic, messageType: types.velocity });
    const topic = new ROSLIB.Topic({ ros, name: pose.topic, messageType: types.pose });
    topic.subscribe((msg) => this.#pose(msg));
  }

  #topicType(ros, topic) {
    return new Promise((resolve) => {
      const timer = setTimeout(() => resolve(null), this.rosTypes.detectTimeoutS * 1000);
      const done = (type) => {
        clearTimeout(timer);
        resolve(type || null);
      };
      ros.getTopicType(topic, done, () => done(null));
    });
  }

  publish(twist) {
    if (this.cmdVel === null) return false;
    const { velocityKind, flavour } = this.types;
    const { frameId } = this.robot.description.velocity;
    // ROS time is the wall clock's: a TwistStamped is stamped with it.
    const stampS = Date.now() / 1000;
    this.cmdVel.publish(
      velocityMessage(velocityKind, flavour, twist.linear, twist.angular, stampS, frameId),
    );
    return true;
  }

  #pose(msg) {
    const pose = poseOf(this.robot.description.pose.type, msg);
    if (pose === null) {
      if (!this.badPoseLogged) this.log.warn(`${this.robot.description.pose.topic}: no pose in it`);
      this.badPoseLogged = true;
      return;
    }
    if (!this.spawnDone) {
      this.spawnDone = true;
      this.#spawnStep(pose);
    }
    this.onPose(pose);
  }

  // The thesis's spawn step: the turtle starts facing "up" (θ = π/2), where the camera looks.
  // A turtlesim's only (the server leaves it off for any other robot).
  #spawnStep(pose) {
    if (this.spawnTheta === null || this.robot.teleportService === null) return;
    const service = new ROSLIB.Service({
      ros: this.ros,
      name: this.robot.teleportService,
      serviceType: this.types.teleport,
    });
    service.callService(
      { x: pose.x, y: pose.y, theta: this.spawnTheta },
      () => this.log.info('spawn step: the turtle turned to π/2'),
      (err) => this.log.error(`spawn step failed: ${err}`),
    );
  }
}
