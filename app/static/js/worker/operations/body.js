// People tracking: the union of the spec's body cascades (full body and upper body), so a person
// is found whether or not their legs are in view; the target is the centre of the largest box.
export { createCascadeOperation as create } from './haar.js';
