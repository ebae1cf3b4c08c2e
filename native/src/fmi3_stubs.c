/* The FMI 3.0 functions these FMUs do not provide, or only for an empty request: types they have
 * no variables of, derivatives, configuration mode (see fmi3_glue.c). Each names what is missing
 * in its error message. */
#include "fmi3_wrapper.h"
#include "partials.h"

#define NO_VARIABLES(get, set, type, name)                                                     \
    fmi3Status get(fmi3Instance instance, const fmi3ValueReference valueReferences[],          \
                   size_t nValueReferences, type values[], size_t nValues)                     \
    {                                                                                          \
        WRAP(get);                                                                            \
        (void)valueReferences, (void)values, (void)nValues;                                    \
        return nValueReferences ? FAIL(w, "%s: this FMU has no %s variables", #get, name)      \
                                : fmi3OK;                                                      \
    }                                                                                          \
    fmi3Status set(fmi3Instance instance, const fmi3ValueReference valueReferences[],          \
                   size_t nValueReferences, const type values[], size_t nValues)               \
    {                                                                                          \
        WRAP(set);                                                                            \
        (void)valueReferences, (void)values, (void)nValues;                                    \
        return nValueReferences ? FAIL(w, "%s: this FMU has no %s variables", #set, name)      \
                                : fmi3OK;                                                      \
    }

NO_VARIABLES(fmi3GetFloat32, fmi3SetFloat32, fmi3Float32, "Float32")
NO_VARIABLES(fmi3GetInt8, fmi3SetInt8, fmi3Int8, "Int8")
NO_VARIABLES(fmi3GetUInt8, fmi3SetUInt8, fmi3UInt8, "UInt8")
NO_VARIABLES(fmi3GetInt16, fmi3SetInt16, fmi3Int16, "Int16")
NO_VARIABLES(fmi3GetUInt16, fmi3SetUInt16, fmi3UInt16, "UInt16")
NO_VARIABLES(fmi3GetUInt32, fmi3SetUInt32, fmi3UInt32, "UInt32")
NO_VARIABLES(fmi3GetUInt64, fmi3SetUInt64, fmi3UInt64, "UInt64")

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                         size_t nValues)
{
    WRAP(fmi3GetBinary);
    (void)valueReferences, (void)valueSizes, (void)values, (void)nValues;
    return nValueReferences ? FAIL(w, "fmi3GetBinary: this FMU has no Binary variables") : fmi3OK;
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues)
{
    WRAP(fmi3SetBinary);
    (void)valueReferences, (void)valueSizes, (void)values, (void)nValues;
    return nValueReferences ? FAIL(w, "fmi3SetBinary: this FMU has no Binary variables") : fmi3OK;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    WRAP(fmi3GetNumberOfVariableDependencies);
    (void)valueReference, (void)nDependencies;
    return FAIL(w, "variable dependencies are given in modelDescription.xml only");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    WRAP(fmi3GetVariableDependencies);
    (void)dependent, (void)elementIndicesOfDependent, (void)independents,
        (void)elementIndicesOfIndependents, (void)dependencyKinds, (void)nDependencies;
    return FAIL(w, "variable dependencies are given in modelDescription.xml only");
}
/* --- partial and output derivatives (partials.c); not provided ----------------------------------------------------------------------------- */

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[],
                                        size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity)
{
    WRAP(fmi3GetDirectionalDerivative);
    if (nSeed != nKnowns || nSensitivity != nUnknowns) { /* every variable is a scalar */
        return FAIL(w, "fmi3GetDirectionalDerivative: nSeed (%zu) must equal nKnowns (%zu) and"
                       " nSensitivity (%zu) nUnknowns (%zu): the variables are scalars",
                    nSeed, nKnowns, nSensitivity, nUnknowns);
    }
    return status3(partials_directional(w->inner, "fmi3GetDirectionalDerivative", unknowns,
                                        nUnknowns, knowns, nKnowns, seed, sensitivity));
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity)
{
    WRAP(fmi3GetAdjointDerivative);
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed,
        (void)sensitivity, (void)nSensitivity;
    return FAIL(w, "adjoint derivatives are not provided");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    WRAP(fmi3EnterConfigurationMode);
    return FAIL(w, "this FMU has no structural parameters (no configuration mode)");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    WRAP(fmi3ExitConfigurationMode);
    return FAIL(w, "this FMU has no structural parameters (no configuration mode)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance,
                                    const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues)
{
    WRAP(fmi3GetOutputDerivatives);
    if (nValues != nValueReferences) { /* every variable is a scalar */
        return FAIL(w, "fmi3GetOutputDerivatives: nValues (%zu) must equal nValueReferences"
                       " (%zu): the variables are scalars", nValues, nValueReferences);
    }
    return status3(partials_output_derivatives(w->inner, "fmi3GetOutputDerivatives",
                                               valueReferences, nValueReferences, orders,
                                               values));
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    WRAP(fmi3EvaluateDiscreteStates);
    return FAIL(w, "fmi3EvaluateDiscreteStates is not provided "
                   "(providesEvaluateDiscreteStates=false)");
}
