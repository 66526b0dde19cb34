// Face tracking: the spec's frontal-face cascade on the reduced frame. The target is the centre
// of the largest face: the nearest person, the one a vehicle should turn to.
export { createCascadeOperation as create } from './haar.js';
