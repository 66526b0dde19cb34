// A JSON Schema validator for the subset pydantic's model_json_schema() emits (app/protocol/
// channels.py): type, const, enum, properties, required, additionalProperties, items,
// prefixItems, min/maxItems, min/maxLength, minimum, maximum, exclusiveMinimum/Maximum,
// anyOf, oneOf (with a discriminator), $ref into $defs. Anything else in a schema is an error,
// so a model that starts using a keyword this file does not know fails loudly, not silently.

const KNOWN = new Set([
  '$defs',
  '$ref',
  'additionalProperties',
  'anyOf',
  'const',
  'default',
  'description',
  'discriminator',
  'enum',
  'exclusiveMaximum',
  'exclusiveMinimum',
  'items',
  'maxItems',
  'maxLength',
  'maximum',
  'minItems',
  'minLength',
  'minimum',
  'oneOf',
  'prefixItems',
  'properties',
  'required',
  'title',
  'type',
]);

const TYPE_CHECKS = {
  null: (v) => v === null,
  boolean: (v) => typeof v === 'boolean',
  integer: (v) => Number.isInteger(v),
  number: (v) => typeof v === 'number' && Number.isFinite(v),
  string: (v) => typeof v === 'string',
  array: (v) => Array.isArray(v),
  object: (v) => v !== null && typeof v === 'object' && !Array.isArray(v),
};

const TYPE_WORDS = {
  null: 'null',
  boolean: 'a boolean',
  integer: 'an integer',
  number: 'a finite number',
  string: 'a string',
  array: 'an array',
  object: 'an object',
};

/**
 * Each problem of `value` against `schema`: [{path: ['boxes', 0], message, kind}] where kind is
 * 'type' (the value has the wrong JSON type) or 'value'; [] when the value is valid.
 */
export function validate(schema, value) {
  const problems = [];
  check(schema, value, [], schema, problems);
  return problems;
}

/** One line naming each bad field, like app/protocol/errors.py: `field "x": must be ...`. */
export function describeProblems(problems) {
  return problems
    .map(({ path, message }) => `field "${path.length ? path.join('.') : 'message'}": ${message}`)
    .join('; ');
}

/** The message types a (discriminated union) schema accepts. */
export function acceptedTypes(schema) {
  return Object.keys(schema.discriminator?.mapping ?? {});
}

function resolve(ref, root) {
  const prefix = '#/$defs/';
  if (!ref.startsWith(prefix) || !(ref.slice(prefix.length) in (root.$defs ?? {}))) {
    throw new Error(`schema.js: cannot resolve $ref ${ref}`);
  }
  return root.$defs[ref.slice(prefix.length)];
}

function check(node, value, path, root, problems) {
  for (const key of Object.keys(node)) {
    if (!KNOWN.has(key)) throw new Error(`schema.js: unsupported keyword "${key}"`);
  }
  const add = (message, at = path, kind = 'value') => problems.push({ path: at, message, kind });
  if (node.$ref !== undefined) {
    check(resolve(node.$ref, root), value, path, root, problems);
    return;
  }
  if (node.discriminator !== undefined) {
    const { propertyName, mapping } = node.discriminator;
    const tag = TYPE_CHECKS.object(value) ? value[propertyName] : undefined;
    if (!Object.hasOwn(mapping, tag)) {
      add(
        `must be one of ${Object.keys(mapping)
          .map((k) => JSON.stringify(k))
          .join(', ')}`,
        [...path, propertyName],
      );
      return;
    }
    check(resolve(mapping[tag], root), value, path, root, problems);
    return;
  }
  const branches = node.anyOf ?? node.oneOf;
  if (branches !== undefined) {
    checkBranches(branches, node.oneOf !== undefined, value, path, root, problems);
    return;
  }
  if ('const' in node && value !== node.const) {
    add(`must be ${JSON.stringify(node.const)}`);
    return;
  }
  if (node.enum !== undefined && !node.enum.includes(value)) {
    add(`must be one of ${node.enum.map((v) => JSON.stringify(v)).join(', ')}`);
    return;
  }
  if (node.type !== undefined) {
    const types = Array.isArray(node.type) ? node.type : [node.type];
    if (!types.some((type) => TYPE_CHECKS[type](value))) {
      add(`must be ${types.map((type) => TYPE_WORDS[type]).join(' or ')}`, path, 'type');
      return;
    }
  }
  if (typeof value === 'number') checkNumber(node, value, add);
  else if (typeof value === 'string') checkString(node, value, add);
  else if (Array.isArray(value)) checkArray(node, value, path, root, problems, add);
  else if (TYPE_CHECKS.object(value)) checkObject(node, value, path, root, problems, add);
}

function checkNumber(node, value, add) {
  if (node.minimum !== undefined && value < node.minimum) add(`must be at least ${node.minimum}`);
  if (node.maximum !== undefined && value > node.maximum) add(`must be at most ${node.maximum}`);
  if (node.exclusiveMinimum !== undefined && value <= node.exclusiveMinimum) {
    add(`must be greater than ${node.exclusiveMinimum}`);
  }
  if (node.exclusiveMaximum !== undefined && value >= node.exclusiveMaximum) {
    add(`must be less than ${node.exclusiveMaximum}`);
  }
}

function checkString(node, value, add) {
  // pydantic counts characters (code points), not UTF-16 units.
  const length = [...value].length;
  if (node.minLength !== undefined && length < node.minLength)
    add(`must have at least ${node.minLength} characters`);
  if (node.maxLength !== undefined && length > node.maxLength)
    add(`must have at most ${node.maxLength} characters`);
}

function checkArray(node, value, path, root, problems, add) {
  if (node.minItems !== undefined && value.length < node.minItems)
    add(`must have at least ${node.minItems} items`);
  if (node.maxItems !== undefined && value.length > node.maxItems)
    add(`must have at most ${node.maxItems} items`);
  const prefix = node.prefixItems ?? [];
  value.forEach((item, i) => {
    const itemSchema = i < prefix.length ? prefix[i] : node.items;
    if (itemSchema !== undefined) check(itemSchema, item, [...path, i], root, problems);
  });
}

function checkObject(node, value, path, root, problems, add) {
  const properties = node.properties ?? {};
  for (const name of node.required ?? []) {
    if (!Object.hasOwn(value, name)) add('is required', [...path, name]);
  }
  for (const [name, item] of Object.entries(value)) {
    if (Object.hasOwn(properties, name)) {
      check(properties[name], item, [...path, name], root, problems);
    } else if (node.additionalProperties === false) {
      add('is not allowed', [...path, name]);
    } else if (typeof node.additionalProperties === 'object') {
      check(node.additionalProperties, item, [...path, name], root, problems);
    }
  }
}

/**
 * anyOf: valid when one branch is; oneOf: when exactly one is. When none is, report the
 * problems of the one branch whose type fits the value (e.g. the object of `Point | null`), or
 * a plain "does not match" when no or several branches could have been meant.
 */
function checkBranches(branches, exactlyOne, value, path, root, problems) {
  const results = branches.map((branch) => {
    const found = [];
    check(branch, value, path, root, found);
    return found;
  });
  const passing = results.filter((found) => found.length === 0).length;
  if (exactlyOne ? passing === 1 : passing >= 1) return;
  if (passing > 1) {
    problems.push({ path, message: 'matches more than one allowed form', kind: 'value' });
    return;
  }
  const typeFits = results.filter(
    (found) => !found.some((p) => p.kind === 'type' && p.path === path),
  );
  if (typeFits.length === 1) problems.push(...typeFits[0]);
  else
    problems.push({
      path,
      message: `must be ${branches.map(describeBranch).join(' or ')}`,
      kind: 'type',
    });
}

function describeBranch(branch) {
  if (branch.$ref !== undefined) return `a ${branch.$ref.split('/').at(-1)}`;
  if (branch.type !== undefined) return TYPE_WORDS[branch.type] ?? branch.type;
  return 'another form';
}
